"""``relnav export``: a sequence (folder, KITTI folder, recording) → a ROS 2 bag or KITTI folder."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer

from relnav.cli._common import console, progress_bar


class ExportFormat(StrEnum):
    """Recording layout written by ``relnav export``."""

    rosbag2 = "rosbag2"
    kitti = "kitti"


class BagStorage(StrEnum):
    """ROS 2 bag storage plugin."""

    sqlite3 = "sqlite3"
    mcap = "mcap"


def export(
    sequence: Path = typer.Argument(
        ..., help="Sequence folder, KITTI folder, plain folder of scans or recording."
    ),
    as_: ExportFormat = typer.Option(
        ...,
        "--as",
        help="rosbag2: a ROS 2 bag folder (PointCloud2 x, y, z, intensity float32); kitti: "
        "velodyne/*.bin + times.txt (+ poses.txt with ground truth).",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Folder to create."),
    sensor: str | None = typer.Option(
        None, "--sensor", help="Second sensor of a sequence folder (scans_<name>/)."
    ),
    topic: str | None = typer.Option(
        None, "--topic", help="PointCloud2 topic to read when SEQUENCE is a recording."
    ),
    out_topic: str = typer.Option("/points", "--out-topic", help="rosbag2: topic written."),
    frame_id: str = typer.Option("lidar", "--frame-id", help="rosbag2: header.frame_id."),
    storage: BagStorage = typer.Option(
        BagStorage.sqlite3, "--storage", help="rosbag2: storage plugin (.db3 or .mcap)."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it exists."),
) -> None:
    """Write a sequence as a recording: a ROS 2 bag or a KITTI odometry folder.

    Points are kept to float32, times to the nanosecond; relnav odometry reads the result.

    A bag has no ground truth (evaluate against the sequence's gt_T_target_sensor.tum: same
    times); a KITTI folder gets poses.txt when the sequence has ground truth.

    Examples: [bold]relnav export seq --as rosbag2 --out seq_bag[/];
    [bold]relnav export seq --as kitti --out seq_kitti[/]
    """
    from relnav.errors import InputError
    from relnav.io import open_sequence
    from relnav.io.export import export_sequence

    if out.exists() and not overwrite:
        raise InputError(f"{out}: already exists (--overwrite replaces it)")
    seq = open_sequence(sequence, sensor=sensor, topic=topic)
    n = len(seq)
    with progress_bar() as bar:
        task = bar.add_task(f"export {as_.value}", total=n)
        path = export_sequence(
            seq,
            out,
            as_.value,
            topic=out_topic,
            frame_id=frame_id,
            storage=storage.value,
            overwrite=overwrite,
            progress=lambda done, total: bar.update(task, completed=done),
        )
    what = f"ROS 2 bag, topic {out_topic}" if as_ is ExportFormat.rosbag2 else "KITTI folder"
    console.print(f"wrote {n} scans to {path} ({what})")


def register(app: typer.Typer) -> None:
    """Register ``relnav export`` on ``app``."""
    app.command("export")(export)
