"""Scans written to folders: the rendered frames as an image session with its manifest."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ...sim.render import RenderedScene
from ...sim.scene import Scene


def rendered_records(frames: list[RenderedScene], readings: np.ndarray, ids: list[str]
                      ) -> list[dict[str, Any]]:
    return [{"id": i, "on": f.on, "off": f.off, "joints": r.tolist()}
            for i, f, r in zip(ids, frames, readings)]


@contextmanager
def scan_folder(out_dir: Any) -> Iterator[Path | None]:
    """A temporary folder whose files take their places in ``out_dir`` when the block ends
    without an error (:func:`hmlvs._io.atomic_folder`, the manifest last); None without
    ``out_dir``."""
    if out_dir is None:
        yield None
        return
    from ..._io import atomic_folder

    with atomic_folder(out_dir, last=("manifest.json", "gauge_block.json")) as tmp:
        yield tmp


def write_scan(out_dir: Any, ids: list[str], frames: list[RenderedScene],
                readings: np.ndarray, image_size: tuple[int, int], robot: Any,
                **extra: Any) -> Any:
    from ...data.manifest import write_image_manifest
    return write_image_manifest(out_dir, ids, [f.on for f in frames], [f.off for f in frames],
                                readings, image_size, robot.name, **extra)


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    from dataclasses import asdict
    return {"primitives": [{"type": type(p).__name__, **asdict(p)} for p in scene.primitives],
            "light": list(scene.light), "ambient_fraction": scene.ambient_fraction}
