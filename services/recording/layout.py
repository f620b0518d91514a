"""The Foxglove layout in docs/foxglove-layout.json (``python -m services.recording.layout >
docs/foxglove-layout.json``): the 3D scene (crater, robot, crane, cameras' cones), both
cameras' previews with their annotations, the crane's error and sideways pull, the cameras'
aim errors. It fits ``stb foxglove`` live and a recording alike: both name the channels the
same (``services.recording.typed``, ``json/<key>``)."""

from __future__ import annotations

import json

from foxglove import layouts as fl

from services.recording.typed import CRATER, SCENE, TF

CAMERAS = ("ptz1", "ptz2")


def _image(camera: str) -> fl.ImagePanel:
    return fl.ImagePanel(title=f"{camera} preview", config=fl.ImageConfig(
        image_mode=fl.ImageModeConfig(
            image_topic=f"/{camera}/image",
            annotations={f"/{camera}/annotations": fl.ImageAnnotationSettings(visible=True)})))


def _plot(title: str, series: list[tuple[str, str]]) -> fl.PlotPanel:
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=path, label=label, enabled=True) for path, label in series],
        show_legend=True))


def layout() -> fl.Layout:
    scene = fl.ThreeDeePanel(title="crater, robot, crane, cameras", config=fl.ThreeDeeConfig(
        follow_tf="world", topics={topic: fl.BaseRendererSceneUpdateTopicSettings(visible=True)
                                   for topic in (SCENE, CRATER, TF)},
        camera_state=fl.ThreeDeeCameraState(distance=9.0, phi=50.0, perspective=True,
                                            target=(0.0, 0.0, 0.0))))
    offload = "json/stb/gantry/offload"
    plots = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(content=_plot("crane error (mm)", [
            (f"{offload}.horizontal_error_mm", "crane to robot, mm")])),
        fl.SplitItem(content=_plot("sideways pull (%)", [
            (f"{offload}.horizontal_share_pct", "sideways pull, %"),
            (f"{offload}.warn_above_pct", "limit, %")])),
        fl.SplitItem(content=_plot("PTZ aim error (°)", [
            (f"json/stb/ptz/{c}/state.aim_error_deg", c) for c in CAMERAS]))])
    images = fl.SplitContainer(direction="column",
                               items=[fl.SplitItem(content=_image(c)) for c in CAMERAS])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=2, content=scene), fl.SplitItem(content=images),
        fl.SplitItem(content=plots)]))


def layout_json() -> str:
    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


if __name__ == "__main__":
    print(layout_json(), end="")
