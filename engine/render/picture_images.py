"""The images a screen pass keeps for monitors' pictures: a monitor's camera with ambient
occlusion, screen reflections or light shafts of its own has them found in images of its
picture's own (``engine/render/monitors.py``), one set by monitor, made again when the
picture's targets or size change, let go with the monitor or the camera's component; and
what the picture drawn now is drawn with, from its pass's ``begin_picture`` to its root's
composite."""
from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Generic, Protocol, TypeVar


class _Released(Protocol):
    def release(self) -> None: ...


Images = TypeVar("Images", bound=_Released)


class PictureImages(Generic[Images]):
    """One pass's images by monitor, and ``drawing``: the picture being drawn (what its root's
    composite reads; None between pictures)."""

    def __init__(self) -> None:
        self._by_monitor: dict[int, Images] = {}
        self.drawing: object | None = None

    def kept(self, monitor: int, fits: Callable[[Images], bool], make: Callable[[], Images]) -> Images:
        """Monitor ``monitor``'s images: those kept where they ``fit``, else new ones (``make``),
        the old let go."""
        images = self._by_monitor.get(monitor)
        if images is None or not fits(images):
            self.drop(monitor)
            images = self._by_monitor[monitor] = make()
        return images

    def drop(self, monitor: int) -> None:
        """Let go of monitor ``monitor``'s images (it went, or its camera no longer asks)."""
        images = self._by_monitor.pop(monitor, None)
        if images is not None:
            images.release()

    def release(self) -> None:
        """Let go of every monitor's images (the pass's release)."""
        for monitor in list(self._by_monitor):
            self.drop(monitor)
        self.drawing = None

    def __len__(self) -> int:
        return len(self._by_monitor)

    def __iter__(self) -> Iterator[Images]:
        return iter(self._by_monitor.values())
