"""``psg-data label``: compute observation labels and store them in a dataset."""

from __future__ import annotations

import click

from psg_data.cli._common import (
    DATASET_HELP,
    Progress,
    dataset_path,
    from_old_spelling,
    handle_errors,
    old_spelling,
    quiet_option,
    setup_logging,
)
from psg_data.cli._errors import ContractCommand

__all__ = ["label_cmd"]


@click.command("label", cls=ContractCommand, epilog=DATASET_HELP)
@click.argument("dataset", metavar="DATASET")
@click.option("--source", "-s", required=True, metavar="SOURCE",
              help="gt | privileged | noisy:P[,P_F] | observed (door states read from the depth) | "
                   "detections:FILE (.parquet or .json) or detections:PATH (ConceptGraphs, Spark-DSG / Khronos or "
                   "HOV-SG scene graphs: a folder per scan named by its scan_id; its psg_mapping.json may set "
                   "sessions, synonyms, classes (the tool's class list), transform and relations: geometric "
                   "(default, the on-top association) or stated (ConceptGraphs' 'a on b' relations instead).")
@click.option("--label-seed", "seed", type=int, default=0, show_default=True,
              help="Seed of the noise (noisy sources); the same option as psg-eval's --label-seed.")
@old_spelling("--seed", "--label-seed", "old_seed", type=int)
@click.option("--valid", "valid_file", type=click.Path(), default=None,
              help="JSON {object_id: [receptacle_id, ...]} of valid receptacles (default: the schedule's support).")
@click.option("--observed", type=click.Choice(["matched", "visibility", "either"]), default="matched",
              show_default=True, help="detections: when a receptacle counts as observed in a scan.")
@click.option("--min-iou", type=float, default=0.25, show_default=True,
              help="detections: minimum 3D IoU to match a receptacle node to an annotated box.")
@click.option("--margin", "margin_m", type=float, default=0.10, show_default=True,
              help="detections: footprint margin of the on-top association, metres.")
@click.option("--detections-format", "detections_format", default="auto", show_default=True,
              type=click.Choice(["auto", "table", "conceptgraphs", "spark-dsg", "hovsg"]),
              help="detections: format of PATH (auto: recognised from the content).")
@click.option("--doors/--no-doors", default=True, show_default=True,
              help="Also write door-state rows (door_id, 'open'/'closed') and door visibility (datasets with doors).")
@click.option("--overwrite", is_flag=True,
              help="Replace labels of this source and recompute visibility (only tables psg-data wrote).")
@quiet_option
@handle_errors
def label_cmd(dataset: str, source: str, seed: int, old_seed: int | None, valid_file: str | None, observed: str,
              min_iou: float, margin_m: float, doors: bool, overwrite: bool, quiet: bool,
              detections_format: str = "auto") -> None:
    """Label a dataset: write tables/labels.parquet (and tables/visibility.parquet).

    Codes per (scan, object, receptacle): 1 present, 0 absent, -1 not observed, -2 receptacle not
    valid for the object. Doors are objects whose receptacles are their states ('open', 'closed').
    Prints edges, observations per edge, code counts and the estimated
    P_M / P_F against the ground-truth schedule (95% Wilson intervals).

    \b
    Examples:
      psg-data label /tmp/lab --source privileged
      psg-data label /tmp/lab --source noisy:0.1 --label-seed 3
      psg-data label /tmp/lab --source observed
      psg-data label /tmp/lab --source detections:/tmp/lab_detections.parquet
      psg-data label /tmp/lab --source detections:/tmp/cg_sessions    # ConceptGraphs sg_cache per scan
      psg-data label /tmp/lab --source detections:/tmp/hydra_dsgs     # Spark-DSG dsg.json / .sparkdsg
      psg-data label /tmp/lab --source detections:/tmp/khronos_map.json --detections-format spark-dsg
      psg-data label /tmp/lab --source detections:/tmp/hovsg_graphs   # HOV-SG objects/*.json per scan
    """
    setup_logging(quiet)
    from psg_data._settings import INT64_MAX, Integral, check_settings
    from psg_data.errors import LabelingError
    from psg_data.labeling import AssociationParams, label_dataset
    from psg_data.labeling._pipeline import _valid_from_file, parse_source
    from psg_data.loaders import open_dataset
    from psg_data.writers._safe_output import check_not_input

    flag = "--seed" if old_seed is not None else "--label-seed"
    seed = from_old_spelling(old_seed, seed, old="--seed", new="--label-seed", new_param="seed")
    check_settings({"seed": Integral(0, INT64_MAX)}, {"seed": seed}, "command line", LabelingError, {"seed": flag})
    parse_source(source)
    assoc = AssociationParams(min_iou=min_iou, margin_m=margin_m, observed=observed)  # checked before any work
    path = dataset_path(dataset, command="psg-data label", quiet=quiet)
    ds = open_dataset(path)
    read = [valid_file, source.split(":", 1)[1] if source.startswith("detections:") else None]
    for table in ("labels", "visibility"):  # what this command writes
        check_not_input(ds.root / "tables" / f"{table}.parquet", read, what="table it writes")
    valid = _valid_from_file(valid_file) if valid_file else None
    prog = Progress("visibility", total=len(ds.scan_ids), unit="scans", quiet=quiet)
    summary = label_dataset(path, source, seed=seed, overwrite=overwrite, progress=prog, valid=valid,
                            association=assoc, doors=doors, detections_format=detections_format)
    if prog.done:
        prog.close()
    for line in summary.lines():
        click.echo(line)
