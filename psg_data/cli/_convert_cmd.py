"""``psg-data convert``: raw recordings -> psg-dataset."""

from __future__ import annotations

from pathlib import Path

import click

from psg_data._executors import SCHEDULER_HELP
from psg_data.cli._common import Progress, handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractCommand, check_jobs


@click.command("convert", cls=ContractCommand)
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@click.argument("out", metavar="OUT", type=click.Path(path_type=Path))
@click.option("--config", "config_file", type=click.Path(path_type=Path),
              help="YAML/JSON file with any conversion setting (command-line options win).")
@click.option("--color-topic", help="Colour topic (sensor_msgs/Image or CompressedImage).")
@click.option("--depth-topic", help="Depth topic (Image 16UC1/32FC1 or compressedDepth).")
@click.option("--camera-info-topic", help="sensor_msgs/CameraInfo topic of the colour camera.")
@click.option("--poses", help="Pose source: tf:WORLD->FRAME, odom:/TOPIC or tum:FILE.")
@click.option("--camera-frame", help="Optical frame of the camera (default: CameraInfo header.frame_id).")
@click.option("--split", help="Split recordings into scans (RTAB-Map: each session): gap:SECONDS at time gaps over "
                              "SECONDS, or slot:SECONDS.")
@click.option("--split-gap", "split_gap", type=float, default=None, metavar="SECONDS", hidden=True,
              help="Former spelling of --split gap:SECONDS (kept for one release).")
@click.option("--keyframes", help="Keep only keyframes: every:N or motion:METRES,DEGREES.")
@click.option("--color-encoding", type=click.Choice(["auto", "png", "jpeg"]), default=None,
              help="Colour images in the dataset (auto: JPEG input is passed through as JPEG).")
@click.option("--depth-scale", "depth_scale_m", type=float, default=None,
              help="Metres per unit of 16-bit depth input (default 0.001; TUM folders 0.0002).")
@click.option("--sync-tolerance", "sync_tolerance_s", type=float, default=None,
              help="Largest colour/depth stamp difference paired, seconds (default 0.02).")
@click.option("--side-dir", "side_dir", type=click.Path(path_type=str),
              help="Folder of side files (site.json, door_states.csv, schedule.csv, scans.csv); default: INPUT when "
                   "it is a directory of recordings (a single recording converts without side files).")
@click.option("--input-format", type=click.Choice(["auto", "ros1", "ros2", "mcap", "tum", "scannet", "rtabmap"]),
              default=None)
@click.option("--image-layout", type=click.Choice(["tar", "files"]), default=None,
              help="Images in one tar archive per scan (default) or one file per image.")
@click.option("--jobs", "-j", type=int, default=1, show_default=True, callback=check_jobs,
              help="CPUs to use (-1: all): scans in parallel worker processes, or encoding threads "
                   "within a scan when there are fewer scans than jobs. 1: one core.")
@click.option("--image-check", type=click.Choice(["none", "structure", "full"]), default=None,
              help="Integrity check of every input image (default structure: PNG chunk CRCs, JPEG markers "
                   "through EOI; full: also inflate PNG data and decode JPEG).")
@click.option("--strict", is_flag=True, default=None,
              help="Refuse the conversion at the first corrupt image (default: skip its frame with a warning).")
@click.option("--overwrite", is_flag=True,
              help="Replace OUT once the new dataset is complete; only a psg-dataset psg-data wrote (or an empty "
                   "folder), never an input or a folder holding other files.")
@click.option("--scheduler", default=None, metavar="local|tcp://HOST:PORT",
              help=SCHEDULER_HELP + " Remote workers must see INPUT and OUT (a shared filesystem).")
@quiet_option
@handle_errors
def convert_cmd(input_path: Path, out: Path, config_file: Path | None, quiet: bool, jobs: int, overwrite: bool,
                scheduler: str | None, **opts: object) -> None:
    """Convert raw recordings in INPUT into the psg-dataset OUT.

    INPUT is a recording (ROS 1 .bag, ROS 2 bag directory with sqlite3 or MCAP storage, .mcap
    file), a TUM RGB-D or ScanNet folder, an RTAB-Map database (.db, one scan per session, poses
    in the map's one frame), or a directory of them with side files (site.json,
    door_states.csv, schedule.csv, scans.csv; a single recording converts without them unless
    --side-dir is given). Frames are associated by header stamps; images and frames that cannot
    be (or whose images are damaged) are counted and reported. An interrupted conversion resumes
    when rerun. Exit codes: 0 done (skipped images are warnings), 1 bad input or output (one
    "error:" line, nothing left behind), 2 bad command line, 130 interrupted (rerun to resume).

    \b
    Examples:
      psg-data convert recordings/ lab/
      psg-data convert long.bag lab/ --split gap:60 --keyframes motion:0.1,10
      psg-data convert run.mcap lab/ --poses tf:map->camera_color_optical_frame -j 2
      psg-data convert rgbd_dataset_freiburg1_xyz/ fr1/ --config tum.yaml
      psg-data convert ~/.ros/rtabmap.db lab/ --split gap:600
    """
    setup_logging(quiet)
    from psg_data.convert import ConvertConfig, convert, load_config

    names = {p.name: p.opts[0] for p in click.get_current_context().command.params if p.name and p.opts}
    cfg = load_config(config_file) if config_file else ConvertConfig()
    split_gap = opts.pop("split_gap", None)
    if split_gap is not None:
        if opts.get("split"):
            raise click.UsageError("--split-gap and --split are the same setting; give one of them")
        click.echo("warning: --split-gap S is now --split gap:S; the old spelling goes in the next release", err=True)
        opts["split"] = f"gap:{split_gap:g}"
    cfg = cfg.merged("command line", names, **opts)
    progress = Progress("convert", unit="frames", quiet=quiet)
    report = convert(input_path, out, config=cfg, overwrite=overwrite, jobs=jobs, progress=progress,
                     scheduler=scheduler)
    progress.close()
    units = {"color": "colour images", "depth": "depth images", "frames": "frames"}
    skipped = "; ".join(f"{sum(r.values())} {units[kind]} ({', '.join(f'{k} {v}' for k, v in r.items())})"
                        for kind, r in report.skipped_by_kind.items() if r)
    click.echo(f"converted {len(report.scans)} scans, {report.frames} frames to {report.output} in "
               f"{report.seconds:.1f} s ({report.mb_per_s:.1f} MB/s)"
               + (f"; resumed {len(report.resumed)} scans" if report.resumed else "")
               + (f"; skipped {skipped}" if skipped else ""))
