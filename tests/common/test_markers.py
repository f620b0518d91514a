"""The marker detector (paper §2.1) on synthetic frames with known ground truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from common.markers import Detection, Spot, annotate, closest, detect

H, W = 576, 704


def disc_frame(rng: np.random.Generator, discs: list[tuple[float, float, float]], *,
               peak: float = 255.0, background: float = 16.0, blur: float = 0.7,
               noise: float = 2.5, shape: tuple[int, int] = (H, W)) -> np.ndarray:
    """Anti-aliased discs (u, v, radius) with soft (blurred) edges and sensor noise."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    image: np.ndarray = np.full(shape, background, np.float64)
    for u, v, r in discs:
        coverage = np.clip(r - np.hypot(cols - u, rows - v) + 0.5, 0, 1)
        image = np.maximum(image, background + coverage * (peak - background))
    if blur:
        image = cv2.GaussianBlur(image, (0, 0), blur)
    image += rng.normal(0, noise, shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def streak_frame(rng: np.random.Generator, u: float, v: float, long_r: float,
                 short_r: float, angle_deg: float) -> np.ndarray:
    image = np.full((H, W), 16, np.uint8)
    cv2.ellipse(image, ((u, v), (2 * long_r, 2 * short_r), angle_deg), 255, -1, cv2.LINE_AA)
    return np.clip(image + rng.normal(0, 2.5, image.shape), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("radius", [2.0, 3.0, 5.0, 8.0, 12.0, 15.0])
def test_centroid_within_a_third_of_a_pixel(rng: np.random.Generator, radius: float) -> None:
    for _ in range(15):
        u, v = rng.uniform(40, W - 40), rng.uniform(40, H - 40)
        result = detect(disc_frame(rng, [(u, v, radius)]))
        assert result.status == "ok", (u, v, radius)
        (marker,) = result.markers
        assert np.hypot(marker.u - u, marker.v - v) < 0.3
        assert marker.roundness < 1.21
        assert abs(marker.radius_long - radius) < 0.35 * radius + 0.6


@pytest.mark.parametrize(("long_r", "short_r", "angle"), [(12, 3, 30), (8, 2, -60), (20, 6, 90),
                                                         (6, 4, 0)])
def test_streaks_and_reflections_are_rejected_by_roundness(
        rng: np.random.Generator, long_r: float, short_r: float, angle: float) -> None:
    result = detect(streak_frame(rng, 300.5, 200.25, long_r, short_r, angle))
    assert result.status == "none" and result.markers == ()
    (region,) = result.regions
    assert region.roundness > 1.21
    assert abs(region.roundness - long_r / short_r) < 0.3 * long_r / short_r
    assert abs(((region.angle_deg - angle + 90) % 180) - 90) < 3, "orientation of the long axis"


def test_a_marker_beside_a_reflection(rng: np.random.Generator) -> None:
    image = np.maximum(streak_frame(rng, 100, 400, 15, 3, 45),
                       disc_frame(rng, [(500.3, 120.7, 6)]))
    result = detect(image)
    assert result.status == "ok" and len(result.regions) == 2
    assert np.hypot(result.markers[0].u - 500.3, result.markers[0].v - 120.7) < 0.3


def test_a_small_marker_close_to_a_glint_is_still_round(rng: np.random.Generator) -> None:
    """A small marker (its shape judged from the blurred spot) a few pixels from a glint a little
    dimmer than itself: the glint must not stretch the marker's ellipse (seen in the gantry
    experiment: the marker was lost once a round, where the track passed a reflection)."""
    glint = np.full((H, W), 16.0)
    cv2.ellipse(glint, ((308, 215), (16, 6), -20), 230, -1, cv2.LINE_AA)
    image = np.maximum(disc_frame(rng, [(300.3, 208.6, 2.6)]), glint.astype(np.uint8))
    result = detect(image)
    assert result.status == "ok", [(r.u, r.v, r.roundness) for r in result.regions]
    (marker,) = result.markers
    assert np.hypot(marker.u - 300.3, marker.v - 208.6) < 0.3


def test_threshold_descends_to_find_a_dim_marker_and_stops_at_t_lim(
        rng: np.random.Generator) -> None:
    # An out-of-focus dim marker: a dome whose top (≈ 212) is below the first thresholds.
    dim = disc_frame(rng, [(321.4, 222.2, 4)], peak=225, blur=1.5, noise=1.0)
    assert 205 < dim.max() < 225
    result = detect(dim, threshold=240, t_lim=203, step=5)
    assert result.status == "ok" and 203 <= result.threshold < dim.max()
    assert np.hypot(result.markers[0].u - 321.4, result.markers[0].v - 222.2) < 0.3
    dimmer = disc_frame(rng, [(321.4, 222.2, 6)], peak=190, blur=0, noise=1.0)
    result = detect(dimmer, threshold=240, t_lim=203)
    assert result.status == "none" and result.threshold == 203


def test_too_many_markers(rng: np.random.Generator) -> None:
    image = disc_frame(rng, [(100, 100, 5), (300, 300, 5), (500, 100, 5)])
    assert detect(image, max_markers=1).status == "too_many"
    result = detect(image, max_markers=3)
    assert result.status == "ok" and len(result.markers) == 3


def test_more_regions_than_the_result_table_holds_at_first(rng: np.random.Generator) -> None:
    """400 markers: more than the kernel's first table has room for (256), so the detector
    grows it and asks again; every marker comes back, and a frame with fewer after it too."""
    grid = [(30.0 + 32 * i, 25.0 + 26 * j, 4.0) for i in range(20) for j in range(20)]
    result = detect(disc_frame(rng, grid), max_markers=1000)
    assert result.status == "ok" and len(result.markers) == len(result.regions) == 400
    found = sorted((round(m.u), round(m.v)) for m in result.markers)
    assert found == sorted((round(u), round(v)) for u, v, _ in grid)
    again = detect(disc_frame(rng, grid[:3]), max_markers=1000)
    assert len(again.markers) == 3


def test_l_min_drops_stray_bright_pixels(rng: np.random.Generator) -> None:
    image = disc_frame(rng, [], noise=0)
    image[rng.integers(0, H, 300), rng.integers(0, W, 300)] = 255
    assert detect(image, l_min=2, min_area=1).regions == ()
    assert len(detect(image, l_min=1, min_area=1, max_markers=1000).regions) > 200


def test_closest_marker_to_the_last_known_position() -> None:
    markers = [Spot(100, 100, 3, 3, 0, 1, 28), Spot(200, 120, 3, 3, 0, 1, 28)]
    assert closest(markers, 190, 100) is markers[1]
    assert closest(markers, 100, 90, max_distance_px=5) is None
    assert closest([], 0, 0) is None


def test_agrees_with_opencv_moments_on_random_frames(rng: np.random.Generator) -> None:
    for _ in range(20):
        discs = [(rng.uniform(20, W - 20), rng.uniform(20, H - 20), rng.uniform(2, 12))
                 for _ in range(rng.integers(1, 6))]
        image = disc_frame(rng, discs)
        result = detect(image, threshold=220, t_lim=220, l_min=1, min_area=0, max_markers=99)
        binary = (image >= 220).astype(np.uint8)
        count, _, stats, centroids = cv2.connectedComponentsWithStats(binary, connectivity=4)
        assert len(result.regions) == count - 1
        ours = sorted((r.area, round(r.u), round(r.v)) for r in result.regions)
        theirs = sorted((int(stats[k, cv2.CC_STAT_AREA]), round(centroids[k, 0]),
                         round(centroids[k, 1])) for k in range(1, count))
        for (a1, u1, v1), (a2, u2, v2) in zip(ours, theirs, strict=True):
            assert a1 == a2 and abs(u1 - u2) <= 1 and abs(v1 - v2) <= 1
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        for contour in contours:
            mom = cv2.moments(contour)
            if mom["m00"] < 10:
                continue
            cu, cv_ = mom["m10"] / mom["m00"], mom["m01"] / mom["m00"]
            nearest = min(result.regions, key=lambda r: np.hypot(r.u - cu, r.v - cv_))
            assert np.hypot(nearest.u - cu, nearest.v - cv_) < 0.5


@pytest.mark.parametrize("frame", [
    np.zeros((0, 0), np.uint8), np.zeros((H, W), np.uint8), np.full((H, W), 255, np.uint8),
    np.full((7, 5), 255, np.uint8), np.zeros((1, 1), np.uint8),
], ids=["empty", "black", "saturated", "odd-sized-saturated", "one-pixel"])
def test_degenerate_frames_give_an_empty_result(frame: np.ndarray) -> None:
    result = detect(frame)
    assert isinstance(result, Detection) and result.status == "none" and result.markers == ()


def test_odd_sized_frame_with_a_marker(rng: np.random.Generator) -> None:
    image = disc_frame(rng, [(30.2, 20.6, 4)], shape=(37, 53))
    result = detect(image)
    assert result.status == "ok" and abs(result.markers[0].u - 30.2) < 0.3


def test_non_contiguous_view_is_fine(rng: np.random.Generator) -> None:
    big = disc_frame(rng, [(220.5, 110.5, 5)], shape=(H + 20, W + 40))
    view = big[10 : H + 10, 20 : W + 20]
    assert not view.flags.c_contiguous
    (marker,) = detect(view).markers
    assert abs(marker.u - 200.5) < 0.3 and abs(marker.v - 100.5) < 0.3


@pytest.mark.parametrize(("frame", "message"), [
    (np.zeros((10, 10, 3), np.uint8), "2-D gray image"),
    (np.zeros((10, 10), np.float32), "8-bit"),
    (np.zeros((10, 10), np.uint16), "8-bit"),
    ([[0, 1], [2, 3]], "numpy array"),
])
def test_wrong_input_is_a_clear_error(frame: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        detect(frame)  # type: ignore[arg-type]


def test_bad_parameters_are_a_clear_error() -> None:
    with pytest.raises(ValueError, match="t_lim"):
        detect(np.zeros((4, 4), np.uint8), threshold=200, t_lim=210)


def test_annotated_image_marks_markers_and_rejects(rng: np.random.Generator) -> None:
    image = np.maximum(streak_frame(rng, 100, 400, 15, 3, 45), disc_frame(rng, [(500, 120, 6)]))
    drawn = annotate(image, detect(image))
    assert drawn.shape == (H, W, 3)
    green = (drawn[..., 1] > 150) & (drawn[..., 2] < 80)
    red = (drawn[..., 2] > 150) & (drawn[..., 1] < 80)
    assert green[100:140, 480:520].any(), "the marker's ellipse in green"
    assert red[370:430, 70:130].any(), "the rejected streak in red"
