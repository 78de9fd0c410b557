"""``run.json``: what made an output folder (method, options, versions, input, timings, flags).

Every folder relnav's odometry writes (``relnav odometry``, each method folder of
``relnav demo``) gets a ``run.json``, so a result can be traced back and rerun::

    {"relnav_run": 1, "command": "odometry", "method": "feature:hods+gcc+svd",
     "preset": "extended", "options": {...}, "versions": {"relnav": "0.1.0", "numpy": ...},
     "sequence": {"kind": "sequence", "path": "seq", "frames": 60,
                  "content_hash": "sha256:..."}, "seed": 0, "timings": {...},
     "flags": {"frames": 60, "flagged": 2, "status": {"ok": 58, "degenerate": 2}},
     "outputs": ["estimate.tum", "diagnostics.csv"], "created_utc": "..."}
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import platform
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from relnav import __version__

__all__ = ["RUN_FILE", "dependency_versions", "read_run_info", "run_info", "write_run_info"]

RUN_FILE = "run.json"

_DEPENDENCIES = (
    "numpy",
    "scipy",
    "numba",
    "rosbags",
    "open3d-cpu",
    "open3d",
    "kiss-icp",
    "small_gicp",
    "evo",
    "rerun-sdk",
)


def dependency_versions() -> dict[str, str]:
    """relnav, Python and the installed versions of relnav's main dependencies."""
    out = {"relnav": __version__, "python": platform.python_version()}
    for name in _DEPENDENCIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return out


def _clean(x: Any) -> Any:
    """JSON-safe copy: NumPy scalars/arrays → builtins, NaN/inf → None, Paths → str."""
    import numpy as np

    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, str | int | float | bool) or x is None:
        return x
    return repr(x)


def run_info(
    *,
    command: str,
    run: Any = None,
    method: str | None = None,
    preset: str | None = None,
    options: dict[str, Any] | None = None,
    sequence: Any = None,
    seed: int | None = None,
    timings: dict[str, float] | None = None,
    outputs: list[str] | None = None,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Build the ``run.json`` document.

    Parameters
    ----------
    command : str
        The producing command (``"odometry"``, ``"demo"`` …).
    run : OdometryRun, optional
        Supplies the method, the expanded options, per-frame timings and flag counts.
    method, preset, options
        Method string, preset name and options (override what ``run`` holds).
    sequence : sequence, optional
        Anything :func:`relnav.io.sources.open_sequence` returns; its path, kind and a content
        hash of its files are recorded.
    seed : int, optional
        Seed of the run (simulation or method), when there is one.
    timings : dict, optional
        Extra wall-clock timings, seconds.
    outputs : list of str, optional
        File names written next to ``run.json``.
    extra : dict, optional
        Merged into the document.
    """
    from relnav.io.sources import content_hash, sequence_description, sequence_sources

    doc: dict[str, Any] = {
        "relnav_run": 1,
        "command": command,
        "created_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "method": method if method is not None else getattr(run, "method", None),
        "preset": preset,
        "options": options if options is not None else dict(getattr(run, "options", {}) or {}),
        "versions": dependency_versions(),
    }
    if sequence is not None:
        desc = sequence_description(sequence)
        files = sequence_sources(sequence)
        root = Path(desc.get("path", "")) if desc.get("path") else None
        desc["frames"] = len(sequence)
        desc["content_hash"] = content_hash(files, root=root if root and root.is_dir() else None)
        desc["n_files_hashed"] = len(files)
        doc["sequence"] = desc
    doc["seed"] = seed
    t: dict[str, float] = {}
    if run is not None and len(getattr(run, "timestamps", ())):
        import numpy as np

        steps = getattr(run, "steps", None) or []
        ft = getattr(run, "frame_time_s", None)
        frame_s = (
            np.asarray(ft, dtype=float)
            if ft is not None
            else np.array([s.time_s for s in steps], dtype=float)
        )
        if len(frame_s):
            t.update(
                total_s=float(frame_s.sum()),
                first_frame_s=float(frame_s[0]),
                median_frame_ms=run.median_time_ms,
                mean_frame_ms=run.mean_time_ms,
            )
        if hasattr(run, "status_counts"):  # kept steps, or a streamed run's diagnostics file
            status = Counter(run.status_counts())
        else:
            status = Counter(str(s.status) for s in steps)
        doc["flags"] = {
            "frames": len(run.timestamps),
            "flagged": int(run.n_flagged),
            "status": dict(sorted(status.items())),
        }
    t.update(timings or {})
    doc["timings"] = t
    if outputs is not None:
        doc["outputs"] = outputs
    doc.update(extra or {})
    return _clean(doc)


def write_run_info(folder: str | Path, doc: dict[str, Any]) -> Path:
    """Write ``doc`` (from :func:`run_info`) to ``folder/run.json``."""
    from relnav.atomic import atomic_write_text

    p = Path(folder) / RUN_FILE
    return atomic_write_text(p, json.dumps(_clean(doc), indent=2, allow_nan=False) + "\n")


def read_run_info(folder: str | Path) -> dict[str, Any] | None:
    """``folder/run.json`` as a dict, or ``None`` when absent or unreadable."""
    p = Path(folder) / RUN_FILE
    if not p.is_file():
        return None
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
