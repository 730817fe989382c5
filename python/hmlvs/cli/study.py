"""hmlvs study: the paper's simulation study (Table 1, Fig. 8)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import app, echo_json, interrupted
from .options import JSON_OPTION


@app.command()
def study(
    quick: bool = typer.Option(
        False, "--quick", help="Fewer runs: 30 LM starts, 5 PSO runs and 200,000 random-search "
        "evaluations per s (about 10 s on 2 cores)."),
    runs_lm: Optional[int] = typer.Option(
        None, "--runs-lm", help="LM starts per s, the same for paper-mode and modern LM "
        "(default 1000, the paper's; quick 30)."),
    runs_pso: Optional[int] = typer.Option(
        None, "--runs-pso", help="PSO runs per s, also polished for PSO+LM (default 10; "
        "quick 5)."),
    evaluations: Optional[int] = typer.Option(
        None, "--evaluations", help="Random-search evaluations per s (default 1,000,000; "
        "quick 200,000)."),
    spreads: Optional[list[float]] = typer.Option(
        None, "--s", help="A spread s of the initial candidates (Eq. 22); repeat for several "
        "(default 0.0001 0.001 0.01 0.1 0.2)."),
    seed: int = typer.Option(0, help="Random seed of the data and of every method."),
    threads: Optional[int] = typer.Option(
        None, help="Worker threads (default: all cores); results do not depend on it."),
    out: Optional[Path] = typer.Option(
        None, "--out", help="Folder for study.md (the tables) and the PNG plots."),
    as_json: bool = JSON_OPTION,
    progress: bool = typer.Option(
        True, "--progress/--no-progress", help="Show a progress bar on stderr."),
) -> None:
    """The paper's simulation study (Table 1, Fig. 8) of the five identification methods.

    RS, paper-mode LM, PSO, modern LM and PSO+LM from the same initial candidates, for each
    spread s.

    Example: hmlvs study --quick --out study-out
    """
    from ..paper import study as st

    try:
        result = st.study(s_values=st.PAPER_S if not spreads else spreads, runs_lm=runs_lm,
                          runs_pso=runs_pso, evaluations=evaluations, quick=quick, seed=seed,
                          threads=threads, progress=progress, out_dir=out)
    except ValueError as e:
        typer.echo(f"error: {' '.join(str(e).split())}", err=True)
        raise typer.Exit(2) from None
    except KeyboardInterrupt as e:
        raise interrupted(e, ": no results written") from None
    if as_json:
        echo_json(result.to_dict())
    else:
        typer.echo(result.table())
        if result.files:
            typer.echo(f"written to {out}: " + ", ".join(p.name for p in result.files))
