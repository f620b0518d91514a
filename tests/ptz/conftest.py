"""The PTZ service fixture shared by the PTZ tests."""

from tests.ptz.test_service import service  # noqa: F401 - a fixture
