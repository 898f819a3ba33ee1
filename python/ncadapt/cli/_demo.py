"""``ncadapt demo``: the main job on shipped data."""

from __future__ import annotations

import shutil
from importlib import resources
from pathlib import Path

import click

from ._common import handle_errors


@click.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=Path("demo-out"),
              show_default=True, help="Folder for the demo's inputs and outputs.")
@click.pass_context
@handle_errors
def demo(ctx, out_dir):
    """Correct a shipped plate program with a shipped probe map.

    Copies the program and the probe grid into OUT, runs ``ncadapt correct`` on them and writes
    ``plate-corrected.ngc`` and ``plate-corrected.json`` beside them.
    """
    from ._correct import correct

    out_dir.mkdir(parents=True, exist_ok=True)
    data = resources.files("ncadapt") / "data"
    for name in ("plate.ngc", "plate_probe.csv"):
        with resources.as_file(data / name) as src:
            shutil.copyfile(src, out_dir / name)
    click.echo(f"demo: correcting {out_dir / 'plate.ngc'} with the probe map {out_dir / 'plate_probe.csv'}", err=True)
    ctx.invoke(correct, program=out_dir / "plate.ngc", field_path=out_dir / "plate_probe.csv", shift=None,
               output=out_dir / "plate-corrected.ngc", max_segment=1.0, chord_tol=0.002, limit=0.5,
               outside="error", method="linear", rapids=False, keep_unsupported=False, clearance=0.0,
               json_path=out_dir / "plate-corrected.json")
    click.echo(f"demo: wrote {out_dir / 'plate-corrected.ngc'} and {out_dir / 'plate-corrected.json'}", err=True)
