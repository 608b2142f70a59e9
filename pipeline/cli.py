"""The ``impactpipe`` command line.

Exit status: 0 success, 1 a stage failed, 2 invalid config or arguments, or a run
directory that another process holds or that cannot be written (nothing written), 130
interrupted (SIGINT/SIGTERM; finished stages and checkpoints are kept).
"""

from __future__ import annotations

import contextlib
import logging
import math
import sys
import time
from pathlib import Path

import click
import yaml

from . import checks, derived, ranks, runstore
from .config import STAGES, ConfigError, load_config
from .lock import RunDirError, run_lock
from .stages import StageInterrupted, resolved_dict, run

log = logging.getLogger("impactpipe")


def _setup_logging(verbose: int, quiet: bool) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s", "%H:%M:%S"))
    handler.setLevel(level)  # a run's run.log (runstore.run_log) lowers the logger, not the console
    root = logging.getLogger("impactpipe")
    root.handlers[:] = [handler]
    root.setLevel(level)


def _load_or_exit(path: str):
    try:
        config = load_config(path)
        values = checks.check(config)
    except ConfigError as exc:
        for message in exc.messages:
            click.echo(message, err=True)
        sys.exit(2)
    for message in checks.warnings(config, values):
        click.echo(message, err=True)
    return config, values


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="impactpipe")
def main() -> None:
    """Hybrid hydrocode-to-N-body simulations of collisions between small bodies."""


@main.command("validate")
@click.argument("config_path", metavar="CONFIG", type=click.Path(dir_okay=False))
def validate_cmd(config_path: str) -> None:
    """Check CONFIG and print it fully resolved with every derived value; exit 2 on errors."""
    config, values = _load_or_exit(config_path)
    document = {"config": resolved_dict(config), "derived": derived.as_plain(values)}
    click.echo(yaml.safe_dump(document, sort_keys=False), nl=False)


@main.command("run")
@click.argument("config_path", metavar="CONFIG", type=click.Path(dir_okay=False))
@click.option("--out", "out_dir", type=click.Path(file_okay=False), help="Run directory (overrides `output`).")
@click.option("--from", "from_stage", type=click.Choice(STAGES), help="Rerun from this stage on.")
@click.option("--stage", "stages", type=click.Choice(STAGES), multiple=True, help="Run only these stages.")
@click.option("--force", is_flag=True, help="Rerun every stage.")
@click.option("-v", "--verbose", count=True, help="More log output.")
@click.option("-q", "--quiet", is_flag=True, help="Warnings and errors only, no progress bars.")
@click.option("--ranks", "nranks", type=click.IntRange(min=1), default=1, show_default=True,
              help="Run the hydro stage on N MPI ranks (launches `mpiexec -n N` with this command; needs "
                   f'{ranks.INSTALL_HINT}); docs/runs.md.')
@click.option("--stage-function", "stage_functions", multiple=True, metavar="STAGE=MODULE:FUNCTION",
              help="Run this function instead of a stage's own (as a sweep's stage_functions); repeatable.")
def run_cmd(config_path: str, out_dir: str | None, from_stage: str | None, stages: tuple[str, ...],
            force: bool, verbose: int, quiet: bool, nranks: int, stage_functions: tuple[str, ...]) -> None:
    """Run the pipeline for CONFIG, resuming finished stages."""
    replaced = _stage_functions_or_exit(stage_functions)
    if nranks > 1:
        _setup_logging(verbose, quiet)
        _exit_if_too_many_ranks(*_load_or_exit(config_path), nranks)
        arguments = ["run", config_path, *(["--out", out_dir] if out_dir else []),
                     *(["--from", from_stage] if from_stage else []), *(f"--stage={s}" for s in stages),
                     *(["--force"] if force else []), *(["-v"] * verbose), *(["--quiet"] if quiet else []),
                     *(f"--stage-function={s}" for s in stage_functions)]
        try:
            status = ranks.launch(nranks, arguments)
        except ranks.RanksUnavailable as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        if status not in ranks.PIPELINE_STATUSES:
            click.echo(f"error: an MPI rank ended abnormally (mpiexec exit status {status}: a rank killed by a signal "
                       f"or out of memory, or a node lost); mpiexec stopped every rank.  The hydro stage's last "
                       f"checkpoint is kept: run the same command again to resume from it.", err=True)
        sys.exit(status)
    comm = ranks.join_world()
    if comm is not None and comm.rank != 0:
        sys.exit(_follow_rank_zero(config_path, comm))
    ranks.watch_launching_process()
    try:
        _run_pipeline(config_path, out_dir, from_stage, stages, force, verbose, quiet, replaced)
    finally:
        ranks.release()


def _exit_if_too_many_ranks(config, values, nranks: int) -> None:
    """Exit 2 with one line, before anything is written, when the mesh has fewer blocks than ranks."""
    from .adapters.hydro import too_many_ranks

    message = too_many_ranks(config, values, nranks)
    if message is not None:
        click.echo(f"error: {message}", err=True)
        sys.exit(2)


def _stage_functions_or_exit(given: tuple[str, ...]) -> dict[str, str]:
    """``--stage-function STAGE=MODULE:FUNCTION`` options as {stage: "module:function"}; exit 2 on a bad one."""
    replaced = {}
    for option in given:
        stage, _, function = option.partition("=")
        if stage not in STAGES or ":" not in function:
            click.echo(f"--stage-function: expected STAGE=package.module:function with STAGE one of "
                       f"{', '.join(STAGES)} (got {option!r})", err=True)
            sys.exit(2)
        replaced[stage] = function
    return replaced


def _follow_rank_zero(config_path: str, comm) -> int:
    """A rank other than 0 under mpiexec: the hydro stage's share of the work, nothing else
    (rank 0 reports every error and owns the run directory); returns the exit status."""
    import signal

    from .adapters.hydro import follow_hydro_stage

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # rank 0 decides when the run stops
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        load_config(config_path)  # rank 0 reports a bad config; this rank exits with the same status
    except ConfigError:
        ranks.wait_for_order(comm)
        return 2
    try:
        return follow_hydro_stage(comm)
    except Exception as exc:  # rank 0 waits for this rank in a step
        ranks.abort(comm, f"the hydro stage failed: {type(exc).__name__}: {exc}")
        raise


def _run_pipeline(config_path: str, out_dir: str | None, from_stage: str | None, stages: tuple[str, ...],
                  force: bool, verbose: int, quiet: bool, stage_functions: dict[str, str]) -> None:
    """``impactpipe run`` in this process (rank 0 of several)."""
    _setup_logging(verbose, quiet)
    config, values = _load_or_exit(config_path)
    comm = ranks.world()
    if comm is not None:
        _exit_if_too_many_ranks(config, values, comm.size)
    run_dir = Path(out_dir or config.output or Path("runs") / config.name)
    try:
        with run_lock(run_dir), runstore.run_log(run_dir):
            summary = run(config, run_dir, stages=stages or None, from_stage=from_stage, force=force,
                          show_progress=not quiet, stage_functions=stage_functions or None)
    except RunDirError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except StageInterrupted as exc:
        click.echo(f"interrupted ({exc}); finished stages and checkpoints are kept in {run_dir}; "
                   "rerun the same command to resume", err=True)
        sys.exit(130)
    except ValueError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except Exception as exc:  # a stage failed: report where, keep what was written
        log.debug("stage failure", exc_info=True)
        click.echo(f"error: {type(exc).__name__}: {exc}", err=True)
        click.echo(f"the last good state and finished stages are kept in {run_dir}", err=True)
        sys.exit(1)
    click.echo(f"outputs in {run_dir}/:")
    for name in sorted(p.name for p in run_dir.iterdir() if not p.name.startswith(".")):
        click.echo(f"  {name}")
    for key in ("M_lr_over_M_T", "Q", "N_lr"):
        if key in summary:
            click.echo(f"{key} = {summary[key]:.4g}")


@main.command("sweep")
@click.argument("sweep_path", metavar="SWEEP", type=click.Path(dir_okay=False))
@click.option("--out", "out_dir", type=click.Path(file_okay=False), help="Sweep directory (overrides `output`).")
@click.option("--backend", type=click.Choice(["local", "dask"]), help="Execution backend (overrides the file).")
@click.option("--scheduler", help="Dask scheduler address (implies --backend dask).")
@click.option("--workers", type=int, help="Parallel runs (default: cores / (threads_per_run x ranks_per_run)).")
@click.option("--ranks-per-run", "ranks_per_run", type=click.IntRange(min=1),
              help="MPI ranks sharing each point's hydro stage (overrides execution.ranks_per_run; needs "
                   f'{ranks.INSTALL_HINT}; docs/sweeps.md, "Points on several MPI ranks").')
@click.option("--reuse-hydro", "reuse_hydro", multiple=True, type=click.Path(file_okay=False), metavar="RUN_DIR",
              help="A finished run whose hydro stage the points with the same hydro settings adopt instead of "
                   "running it (e.g. to add hand-off seeds to earlier runs); repeatable.")
@click.option("-v", "--verbose", count=True, help="More log output.")
@click.option("-q", "--quiet", is_flag=True, help="Warnings and errors only, no progress bar.")
def sweep_cmd(sweep_path: str, out_dir: str | None, backend: str | None, scheduler: str | None,
              workers: int | None, ranks_per_run: int | None, reuse_hydro: tuple[str, ...], verbose: int,
              quiet: bool) -> None:
    """Run every point of the sweep file SWEEP (a grid or a Q*_D search); resumes where it stopped."""
    from impactpipe.analysis.qstar import plus_minus

    from .sweep import SweepError, load_sweep, run_sweep, sweep_status

    _setup_logging(verbose, quiet)
    given = {"backend": "dask" if scheduler else backend, "scheduler": scheduler, "workers": workers,
             "ranks_per_run": ranks_per_run}
    try:
        sweep = load_sweep(sweep_path, out_dir, execution={k: v for k, v in given.items() if v is not None})
    except SweepError as exc:
        for message in exc.messages:
            click.echo(message, err=True)
        sys.exit(2)
    try:
        result = run_sweep(sweep, show_progress=not quiet, reuse_runs=list(reuse_hydro),
                           report=_point_lines(quiet))
    except SweepError as exc:
        for message in exc.messages:
            click.echo(message, err=True)
        sys.exit(2)
    except RunDirError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    status = sweep_status(sweep.directory)
    click.echo(f"sweep {sweep.spec.name}: {status['total']} points, "
               + ", ".join(f"{n} {s}" for s, n in sorted(status["counts"].items())))
    for record in result["qstar"]:
        scatter = (f", M_lr/M_T standard deviation between replicates {record['replicate_std']:.3f}"
                   if math.isfinite(record.get("replicate_std", float("nan"))) else "")
        qstar = plus_minus(record.get("Qstar_D", float("nan")), record.get("Qstar_D_uncertainty", float("nan")), ".4g")
        group = ", ".join(f"{k}={record[k]}" for k in sweep.spec.axis_values() if k in record)
        click.echo(f"  Q*_D = {qstar} J/kg ({record['status']}{scatter})" + (f" for {group}" if group else ""))
        if "Qstar_D_handoff_error" in record:
            click.echo(f"    hand-off-time error {record['Qstar_D_handoff_error']:.4g} J/kg (standard deviation of "
                       f"Q*_D over the hand-off times; slope {record['Qstar_D_handoff_slope']:.4g} J/kg per s, "
                       f"{record['handoff_status']})")
    for ladder in result["resolution"]:
        group = ", ".join(f"{k}={ladder[k]}" for k in sweep.spec.axis_values() if k in ladder)
        handoff = (f"; hand-off time +- {ladder['handoff_error']:.4g} J/kg (finest rung)"
                   if "handoff_error" in ladder else "")
        click.echo(f"  {ladder['summary'] or ladder['status']}{handoff}" + (f" for {group}" if group else ""))
    tables = ["results.csv", "results.h5"] + (["replicates.csv"] if sweep.spec.replicates else []) \
        + (["qstar.csv"] if result["qstar"] else []) + (["qstar_resolution.csv"] if result["resolution"] else [])
    click.echo(f"tables in {sweep.directory}/: {', '.join(tables)}")
    if status["failed"]:
        sys.exit(1)


def _point_lines(quiet: bool):
    """Where a sweep's line per point start and end goes: standard output when that is not a
    terminal (``impactpipe sweep ... > log``), else the log (:func:`impactpipe.pipeline.sweep.
    open_runner` logs them when no bar is shown); nowhere with --quiet."""
    if quiet or sys.stdout.isatty():
        return None
    return lambda line: click.echo(f"{time.strftime('%H:%M:%S')} {line}")


@main.command("sweep-status")
@click.argument("sweep_dir", metavar="SWEEP_DIR", type=click.Path(file_okay=False, exists=True))
def sweep_status_cmd(sweep_dir: str) -> None:
    """Show how far the sweep in SWEEP_DIR has got and why points failed."""
    from .sweep import sweep_status

    try:
        status = sweep_status(sweep_dir)
    except FileNotFoundError as exc:
        click.echo(str(exc), err=True)
        sys.exit(2)
    done = status["counts"].get("complete", 0)
    click.echo(f"{done}/{status['total']} points complete; "
               + ", ".join(f"{n} {s}" for s, n in sorted(status["counts"].items())))
    for name, error in status["failed"].items():
        click.echo(f"failed {name}: {error}")


def _load_run_config(run_dir: str):
    from .stages import RESOLVED_CONFIG_FILE

    path = Path(run_dir) / RESOLVED_CONFIG_FILE
    if not path.is_file():
        click.echo(f"{run_dir}: no {RESOLVED_CONFIG_FILE}; is this a run directory?", err=True)
        sys.exit(2)
    return _load_or_exit(str(path))[0]


@main.command("analyze")
@click.argument("run_dir", metavar="RUN_DIR", type=click.Path(file_okay=False, exists=True))
@click.option("--out", "out_dir", type=click.Path(file_okay=False),
              help="Write the analysis to this directory instead (RUN_DIR's finished stages are linked there, "
                   "copied where linking is impossible): a read-only run is analysed this way.")
@click.option("-v", "--verbose", count=True, help="More log output.")
@click.option("-q", "--quiet", is_flag=True, help="Warnings and errors only.")
def analyze_cmd(run_dir: str, out_dir: str | None, verbose: int, quiet: bool) -> None:
    """Rerun the analysis of RUN_DIR: analysis.h5 and the figures in RUN_DIR/plots (or --out)."""
    from .stages import adopt_stages

    _setup_logging(verbose, quiet)
    config = _load_run_config(run_dir)
    target = Path(out_dir or run_dir)
    try:
        with run_lock(target):
            if out_dir is not None and target.resolve() != Path(run_dir).resolve():
                adopt_stages(target, Path(run_dir), config)
            summary = run(config, target, stages=["analysis"], from_stage="analysis", show_progress=not quiet)
    except RunDirError as exc:
        hint = "" if out_dir else f"; `impactpipe analyze {run_dir} --out DIR` writes the analysis elsewhere"
        click.echo(f"error: {exc}{hint}", err=True)
        sys.exit(2)
    click.echo(f"analysis written to {target / 'analysis.h5'} and {target / 'plots'}/")
    for key in ("Q", "M_lr_over_M_T", "M_slr_over_M_T", "N_lr"):
        if key in summary:
            click.echo(f"{key} = {summary[key]:.4g}")


@main.command("qstar")
@click.argument("run_dirs", metavar="RUN_DIR_OR_SWEEP_DIR...", nargs=-1, required=True,
                type=click.Path(file_okay=False, exists=True))
@click.option("--by", "by", type=click.Choice(["velocity", "projectile_radius"]), default="velocity",
              show_default=True, help="The variable the runs differ in (gives the critical value).")
@click.option("--common-velocity", type=float, help="Also give Q*_D moved to this impact speed (m/s) with mu.")
@click.option("--mu", type=float, default=0.45, show_default=True, help="Point-source coupling exponent.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=".", show_default=True,
              help="Directory for the tables and figures.")
def qstar_cmd(run_dirs: tuple[str, ...], by: str, common_velocity: float | None, mu: float, out_dir: str) -> None:
    """Fit Q*_D over finished runs: weighted line of M_lr/M_T against Q, crossing 0.5.

    A sweep directory (one with points.json) stands for its finished points: the runs of
    the sweep as last run, not every directory in its runs/ (which may hold the points of
    an earlier version of the sweep).  Runs are grouped by target radius; each group gets its
    fit, table and figure (with the published laws for comparison).  Runs of one target at
    several resolutions (hydro.cells_per_projectile_radius) are fitted per resolution, and
    Q*_D gets its resolution error over that ladder (Richardson, refused where the observed
    order says it cannot be trusted; :mod:`impactpipe.analysis.resolution_error`), beside
    the fit's error from the runs' scatter.  Runs of one resolution handed off at several
    times are also fitted per time, and Q*_D gets its hand-off-time error over them
    (:mod:`impactpipe.analysis.handoff_error`, ``qstar_handoff*.csv``).  Five or more target
    radii also get the fit of Q*_D(R) = q_b R^alpha + rho q_g R^beta (at each radius's finest
    resolution).
    """
    from impactpipe.analysis.energies import fit_qstar_size_law
    from impactpipe.analysis.resolution_error import qstar_resolution_error, write_resolution_table

    from .stages import read_summary
    from .sweep import POINTS_FILE, finished_run_dirs

    expanded = []
    for path in run_dirs:
        if (Path(path) / POINTS_FILE).is_file():
            found = finished_run_dirs(path)
            click.echo(f"{path}: {len(found)} finished points of the sweep")
            expanded += found
        else:
            expanded.append(path)
    run_dirs = tuple(expanded)
    runs = []
    for run_dir in run_dirs:
        summary = read_summary(run_dir)
        missing = [k for k in ("Q", "M_lr_over_M_T", "N_lr") if k not in summary]
        if missing:
            click.echo(f"{run_dir}: summary.json lacks {', '.join(missing)} (has the analysis stage run?)", err=True)
            sys.exit(2)
        config = _load_run_config(run_dir)
        values = derived.derive(config)
        runs.append({"dir": Path(run_dir), "summary": summary, "config": config, "values": values})
    groups: dict[float, list[dict]] = {}
    for run in runs:
        groups.setdefault(run["config"].scene.target.radius, []).append(run)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sizes = []
    for radius, group in sorted(groups.items()):
        suffix = "" if len(groups) == 1 else f"_R{radius:g}"
        ladder: dict[float, list[dict]] = {}
        for run in group:
            ladder.setdefault(float(run["config"].hydro.cells_per_projectile_radius), []).append(run)
        fits = {}
        for cells, rung in sorted(ladder.items()):
            label = f"R_T = {radius:g} m" + (f", {cells:g} cells per R_P" if len(ladder) > 1 else "")
            rung_suffix = suffix + (f"_n{cells:g}" if len(ladder) > 1 else "")
            fits[cells] = _qstar_fit(rung, by, label, out, rung_suffix, radius, common_velocity, mu)
            _handoff_time_fits(rung, label, out / f"qstar_handoff{rung_suffix}.csv")
        if len(ladder) > 1:
            cells = sorted(fits)
            resolution = qstar_resolution_error(cells, [fits[n].qstar for n in cells],
                                                [fits[n].qstar_err for n in cells],
                                                brackets=[fits[n].brackets for n in cells])
            click.echo(f"R_T = {radius:g} m: {resolution.describe()}")
            write_resolution_table(out / f"qstar_resolution{suffix}.csv", resolution)
        finest = fits[max(fits)]
        sizes.append((radius, finest.qstar, group[0]["values"]["target_reference_density"]))
    if len(sizes) >= 5:
        law = fit_qstar_size_law([s[0] for s in sizes], [s[1] for s in sizes], [s[2] for s in sizes])
        click.echo(f"Q*_D(R) = {law.q_b:.3g} R^{law.alpha:.3f} + rho {law.q_g:.3g} R^{law.beta:.3f} "
                   f"(R in m, J/kg; rms log10 residual {law.rms_log10:.3f})")
    elif len(sizes) > 1:
        click.echo(f"{len(sizes)} target radii: the size-law fit needs at least 5")
    click.echo(f"wrote tables and figures to {out}/")


def _handoff_time_fits(group: list[dict], label: str, path: Path) -> None:
    """Runs of one rung handed off at several times: Q*_D fitted at each time and the
    hand-off-time error over them (:mod:`impactpipe.analysis.handoff_error`), printed and
    written to ``path``; nothing for runs handed off at one time."""
    from impactpipe.analysis.handoff_error import fit_by_handoff_time, write_handoff_table

    times = [run["summary"].get("handoff_time", run["config"].handoff.time) for run in group]
    if None in times or len(set(times)) < 2:
        return
    result, problems = fit_by_handoff_time(times, *([r["summary"][k] for r in group]
                                                     for k in ("Q", "M_lr_over_M_T", "N_lr")))
    for line in problems:
        click.echo(f"{label}, {line}", err=True)
    if result is not None:
        click.echo(f"{label}: {result.describe()}")
        write_handoff_table(path, result)


def _qstar_fit(group: list[dict], by: str, label: str, out: Path, suffix: str, radius: float,
               common_velocity: float | None, mu: float):
    """Fit Q*_D over one group of runs (one target radius and resolution); print, table and figure."""
    import numpy as np

    from impactpipe.analysis.energies import comparison_laws, scale_qstar_to_velocity
    from impactpipe.analysis.plots import plot_qstar
    from impactpipe.analysis.qstar import fit_qstar, plus_minus, write_qstar_table

    q = np.array([r["summary"]["Q"] for r in group])
    mlr = np.array([r["summary"]["M_lr_over_M_T"] for r in group])
    n_lr = np.array([r["summary"]["N_lr"] for r in group])
    swept = np.array([r["config"].scene.impact.velocity if by == "velocity" else r["config"].scene.projectile.radius
                      for r in group])
    try:
        fit = fit_qstar(q, mlr, n_lr, **{by: swept})
    except ValueError as exc:
        click.echo(f"{label}: error: {exc}", err=True)
        sys.exit(1)
    rho = group[0]["values"]["target_reference_density"]
    gamma = group[0]["values"]["projectile_mass"] / group[0]["values"]["target_mass"]
    grid = np.geomspace(min(radius / 10.0, 1.0e2), max(radius * 10.0, 1.0e5), 60)
    laws = {name: (grid, values) for name, values in comparison_laws(grid, rho, gamma).items()}
    write_qstar_table(out / f"qstar{suffix}.csv", q, mlr, n_lr, fit, labels=[r["dir"].name for r in group],
                      **{by: swept})
    plot_qstar(out / f"qstar{suffix}.png", q, mlr, n_lr, fit, target_radius=radius, comparisons=laws)
    click.echo(f"{label}: Q*_D = {plus_minus(fit.qstar, fit.qstar_err, '.4g')} J/kg "
               f"from {int(np.sum(fit.used))} of {len(q)} runs")
    critical = fit.critical_velocity if by == "velocity" else fit.critical_radius
    critical_err = fit.critical_velocity_err if by == "velocity" else fit.critical_radius_err
    unit = "m/s" if by == "velocity" else "m"
    click.echo(f"critical {by.replace('_', ' ')} = {plus_minus(critical, critical_err, '.4g')} {unit}")
    click.echo("slope of M_lr/M_T against Q/Q*_D = "
               f"{plus_minus(fit.normalized_slope, fit.normalized_slope_err, '.3f')}")
    if fit.replicated_q:
        where = ("included in the error" if np.isfinite(fit.qstar_err)
                 else "no error bar: fewer than three distinct Q and not every Q repeated")
        click.echo(f"replicates: {fit.replicated_q} Q values run more than once; standard deviation of "
                   f"M_lr/M_T at the same Q = {fit.replicate_std:.3f} ({where})")
    if common_velocity is not None:
        v_from = critical if by == "velocity" else float(group[0]["config"].scene.impact.velocity)
        moved = float(scale_qstar_to_velocity(fit.qstar, v_from, common_velocity, mu))
        click.echo(f"Q*_D at {common_velocity:g} m/s (mu = {mu:g}) = {moved:.4g} J/kg")
    if not fit.brackets:
        click.echo("warning: the runs do not bracket M_lr/M_T = 0.5; Q*_D is an extrapolation", err=True)
    return fit


@main.command("plot")
@click.argument("run_dir", metavar="RUN_DIR", type=click.Path(file_okay=False, exists=True))
@click.option("--field", default="pressure", show_default=True,
              help="density, pressure, temperature, specific_internal_energy, sound_speed, speed, volume_fraction")
@click.option("--time", "at_time", type=float, help="Snapshot time (s); the nearest snapshot is used (default: last).")
@click.option("--tracers", "tracer_plot", is_flag=True, help="Peak pressure against distance along the tracer ray "
              "next to the axis, instead of a field slice.")
@click.option("--out", "out_path", type=click.Path(),
              help="Output PNG, or a directory for the default file name (default RUN_DIR/plots/...); "
                   "a read-only run is plotted this way.")
def plot_cmd(run_dir: str, field: str, at_time: float | None, tracer_plot: bool, out_path: str | None) -> None:
    """Write a PNG of a hydro snapshot field (with block outlines) or of the tracers' peak pressures."""
    from impactpipe.hydro.output.io import read_tracers
    from impactpipe.hydro.output.lookup import find_snapshot
    from impactpipe.hydro.output.plots import FIELDS, plot_peak_pressure_along_axis_ray, plot_snapshot

    path = Path(run_dir) / "hydro.h5"
    if not path.is_file():
        click.echo(f"{run_dir}: no hydro.h5 (has the hydro stage finished?)", err=True)
        sys.exit(2)
    if tracer_plot:
        tracers = read_tracers(path)
        if tracers is None:
            click.echo(f"{path}: no tracers (hydro.tracers.enabled was off)", err=True)
            sys.exit(2)
        config = _load_run_config(run_dir)
        target = _figure_path(run_dir, out_path, "tracers_peak_pressure.png")
        with _writable(target, out_path):
            slope = plot_peak_pressure_along_axis_ray(target, tracers, impact_point=(0.0, config.scene.target.radius))
        click.echo(f"wrote {target}; peak pressure falls with distance as r^{slope:.2f}")
        return
    if field not in FIELDS:
        click.echo(f"--field: unknown field '{field}' (allowed: {', '.join(FIELDS)})", err=True)
        sys.exit(2)
    snapshot, index = find_snapshot(path, time=at_time)
    target = _figure_path(run_dir, out_path, f"{field}_t{snapshot.time:.4g}s.png")
    with _writable(target, out_path):
        plot_snapshot(target, snapshot, field)
    click.echo(f"wrote {target} (snapshot {index}, t = {snapshot.time:.6g} s)")


def _figure_path(run_dir: str, out_path: str | None, name: str) -> Path:
    """Where a figure goes: ``--out`` if it names a PNG, ``name`` in the ``--out`` directory, else
    RUN_DIR/plots/``name``."""
    if out_path is None:
        return Path(run_dir) / "plots" / name
    out = Path(out_path)
    return out if out.suffix.lower() == ".png" else out / name


@contextlib.contextmanager
def _writable(target: Path, out_path: str | None):
    """Around writing ``target``: a place that cannot be written exits 2 with one line, not a traceback."""
    try:
        yield
    except OSError as exc:
        hint = "" if out_path else "; give --out DIR or --out FILE.png to write it elsewhere"
        click.echo(f"error: cannot write {target}: {exc.strerror or exc}{hint}", err=True)
        sys.exit(2)


@main.command("fragments")
@click.argument("run_dir", metavar="RUN_DIR", type=click.Path(file_okay=False, exists=True))
@click.option("--time", "at_time", type=float, help="Snapshot time (s); the nearest snapshot is used (default: last).")
@click.option("--material", "materials", multiple=True,
              help="Material of the body that breaks (repeatable; default: the target's material).")
@click.option("--max-damage", type=click.FloatRange(0.0, 1.0, min_open=True), default=0.99, show_default=True,
              help="Cells at or above this damage are broken and join no fragment.")
@click.option("--min-fill", type=click.FloatRange(0.0, 1.0, min_open=True), default=0.5, show_default=True,
              help="Least volume fraction of the body's materials in a fragment's cell.")
@click.option("--experiment", type=click.Choice(["none", "nakamura-fujiwara"]), default="none", show_default=True,
              help="Print and plot a laboratory experiment's fragments beside the run's.")
@click.option("--top", type=click.IntRange(min=1), default=10, show_default=True, help="Fragments to list.")
@click.option("--out", "out_path", type=click.Path(),
              help="Output PNG, or a directory for the default file name (default RUN_DIR/plots/fragments.png).")
def fragments_cmd(run_dir: str, at_time: float | None, materials: tuple[str, ...], max_damage: float,
                  min_fill: float, experiment: str, top: int, out_path: str | None) -> None:
    """Find the intact fragments of the target in a hydro snapshot (RUN_DIR/fragments.h5), print the largest
    and plot their cumulative mass distribution and speeds (docs/analysis.md, "Fragments")."""
    from impactpipe.analysis.fragments import NAKAMURA_FUJIWARA_1991
    from impactpipe.analysis.plots import plot_fragments

    from .fragments import run_fragments
    from .stages import RESOLVED_CONFIG_FILE

    config = _load_run_config(run_dir)
    if not (Path(run_dir) / "hydro.h5").is_file():
        click.echo(f"{run_dir}: no hydro.h5 (has the hydro stage finished?)", err=True)
        sys.exit(2)
    names = list(materials) or [config.scene.target.material]
    half_domain = bool((derived.derive(config).get("domain") or {}).get("half_domain", False))
    resolved = (Path(run_dir) / RESOLVED_CONFIG_FILE).read_text()
    try:
        fragments, target_mass, snapshot = run_fragments(Path(run_dir), names, half_domain, at_time, min_fill,
                                                         max_damage, resolved)
    except ValueError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    reference = None if experiment == "none" else NAKAMURA_FUJIWARA_1991
    fraction = fragments.mass / target_mass
    click.echo(f"t = {snapshot.time:.6g} s: {fragments.count} fragment{'' if fragments.count == 1 else 's'} of "
               f"{', '.join(names)} "
               f"(damage < {max_damage:g}, fill >= {min_fill:g}); M_T = {target_mass:.6g} kg, "
               f"{fraction.sum():.4f} of it in fragments")
    click.echo(f"{'#':>3} {'m/M_T':>9} {'speed m/s':>10} {'a (m)':>10} {'b/a':>6} {'c/a':>6} {'cells':>7}")
    for i in range(min(top, fragments.count)):
        a, b, c = fragments.semi_axes[i]
        click.echo(f"{i + 1:>3} {fraction[i]:>9.4g} {fragments.speed[i]:>10.4g} {a:>10.4g} "
                   f"{b / a if a > 0 else 0.0:>6.3f} {c / a if a > 0 else 0.0:>6.3f} {fragments.cells[i]:>7d}")
    if reference is not None:
        click.echo(f"{reference.reference}: largest fragment {reference.largest_fraction:g} of M_T at "
                   f"{reference.largest_speed:g} m/s; others V = {reference.speed_coefficient:g} "
                   f"(m/M_T)^{reference.speed_exponent:g} m/s")
    target = _figure_path(run_dir, out_path, "fragments.png")
    if fragments.count:
        with _writable(target, out_path):
            plot_fragments(target, fraction, fragments.speed, experiment=reference)
        click.echo(f"wrote {Path(run_dir) / 'fragments.h5'} and {target}")


@main.command("export")
@click.argument("run_dir", metavar="RUN_DIR", type=click.Path(file_okay=False, exists=True))
@click.option("--time", "at_time", type=float, help="Snapshot time (s); the nearest snapshot is used (default: last).")
@click.option("--all", "every", is_flag=True, help="Export every snapshot (RUN_DIR/export/hydro_<index>.vtkhdf).")
@click.option("--format", "file_format", type=click.Choice(["vtkhdf"]), default="vtkhdf", show_default=True,
              help="vtkhdf: VTKHDF unstructured grid of the leaf cells, for ParaView >= 5.11.")
@click.option("--out", "out_path", type=click.Path(dir_okay=False),
              help="Output file (default RUN_DIR/export/hydro_<index>.vtkhdf).")
def export_cmd(run_dir: str, at_time: float | None, every: bool, file_format: str, out_path: str | None) -> None:
    """Write hydro snapshots of RUN_DIR for ParaView (docs/visualisation.md)."""
    import h5py

    from impactpipe.hydro.output.export import write_vtkhdf
    from impactpipe.hydro.output.lookup import find_snapshot, hydro_file, snapshot_times

    if every and (at_time is not None or out_path):
        click.echo("--all writes every snapshot to RUN_DIR/export/; it takes no --time or --out", err=True)
        sys.exit(2)
    try:
        path = hydro_file(run_dir)
    except FileNotFoundError:
        click.echo(f"{run_dir}: no hydro.h5 (has the hydro stage finished?)", err=True)
        sys.exit(2)
    with h5py.File(path, "r") as fh:
        provenance = {key: value for key, value in fh.attrs.items() if isinstance(value, str)}
    indices = range(len(snapshot_times(path))) if every else [None]
    for wanted in indices:
        try:
            snapshot, index = find_snapshot(path, time=at_time, index=wanted)
        except KeyError as exc:
            click.echo(f"error: {exc.args[0]}", err=True)
            sys.exit(2)
        target = Path(out_path or Path(run_dir) / "export" / f"hydro_{index:04d}.{file_format}")
        write_vtkhdf(snapshot, target, {**provenance, "source": str(path), "snapshot_index": str(index)})
        click.echo(f"wrote {target} (snapshot {index}, t = {snapshot.time:.6g} s)")


@main.command("handoff-scan")
@click.argument("config_path", metavar="CONFIG", type=click.Path(dir_okay=False))
@click.option("--times", required=True, help="Hand-off times in seconds, comma-separated (e.g. 4,6,8,10,12,15).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), help="Directory (default runs/<name>-handoff-scan).")
@click.option("--workers", type=int, help="Parallel runs for the hand-off points.")
@click.option("-v", "--verbose", count=True, help="More log output.")
@click.option("-q", "--quiet", is_flag=True, help="Warnings and errors only, no progress bar.")
def handoff_scan_cmd(config_path: str, times: str, out_dir: str | None, workers: int | None, verbose: int,
                     quiet: bool) -> None:
    """Run the hydro stage once, hand off at each of --times, reaccumulate and analyse each."""
    from .handoff_scan import handoff_scan, slope_text
    from .sweep import SweepError

    _setup_logging(verbose, quiet)
    config, _ = _load_or_exit(config_path)
    try:
        values = [float(t) for t in times.split(",") if t.strip()]
    except ValueError:
        click.echo(f"--times: expected comma-separated seconds (got {times!r})", err=True)
        sys.exit(2)
    out = Path(out_dir or Path("runs") / f"{config.name}-handoff-scan")
    try:
        result = handoff_scan(config_path, values, out, show_progress=not quiet,
                              execution={"workers": workers} if workers else None)
    except (SweepError, ValueError, RunDirError) as exc:
        click.echo(str(exc), err=True)
        sys.exit(2)
    for t, m in zip(result["times"], result["mlr_over_mt"]):
        click.echo(f"t = {t:g} s: M_lr/M_T = {m:.4g}")
    click.echo(slope_text(result["slope"], result["slope_err"], result["n_late"], result["late_from"]))
    click.echo(f"wrote {out / 'handoff_scan.csv'} and {out / 'handoff_scan.png'}")


@main.command("convergence")
@click.argument("config_path", metavar="CONFIG", type=click.Path(dir_okay=False))
@click.option("--vary", "varies", multiple=True, required=True, metavar="KEY=V1,V2,...",
              help="One ladder: a config key and its values (e.g. hydro.cells_per_projectile_radius=5,10,20,40); "
                   "repeat for more ladders, each run with the other keys at the config's values.")
@click.option("--depths", default="1,2,4", show_default=True,
              help="Depths of the peak-pressure answers, in projectile radii below the impact point.")
@click.option("--tolerance", type=float, default=0.05, show_default=True,
              help="Report the cheapest rung within this of the extrapolated M_lr/M_T.")
@click.option("--handoff-times", default=None, metavar="T1,T2,...",
              help="Hand off every rung at each of these times (s) from one hydro run and take the mean "
                   "M_lr/M_T over them (e.g. 12,13.5,15, after 4 target sound-crossing times): averages "
                   "out the reaccumulation's scatter and the hand-off time's trend.  Default the config's "
                   "handoff.window.")
@click.option("--single-handoff", is_flag=True,
              help="Hand off at handoff.time only, even where the config sets a handoff.window.")
@click.option("--seeds", type=int, default=None, metavar="N",
              help="Hand off every rung with the seeds 1..N (ring phases and velocity noise) from its one hydro "
                   "run and take the mean M_lr/M_T, with its standard error (sem column) and the 68 % "
                   "range of the Richardson estimate under those errors.")
@click.option("--reuse-hydro", "reuse_hydro", multiple=True, type=click.Path(file_okay=False), metavar="RUN_DIR",
              help="A finished run whose hydro stage the rungs with the same hydro settings adopt instead of "
                   "running it (e.g. the base config's run, for N-body or hand-off ladders); repeatable.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), help="Directory (default runs/<name>-convergence).")
@click.option("--backend", type=click.Choice(["local", "dask"]), default="local", show_default=True,
              help="Execution backend of the sweep machinery.")
@click.option("--scheduler", help="Dask scheduler address (implies --backend dask).")
@click.option("--workers", type=int, help="Parallel runs (default: cores). Wall times are shared-machine times.")
@click.option("-v", "--verbose", count=True, help="More log output.")
@click.option("-q", "--quiet", is_flag=True, help="Warnings and errors only, no progress bar.")
def convergence_cmd(config_path: str, varies: tuple[str, ...], depths: str, tolerance: float,
                    handoff_times: str | None, single_handoff: bool, seeds: int | None,
                    reuse_hydro: tuple[str, ...], out_dir: str | None,
                    backend: str, scheduler: str | None, workers: int | None, verbose: int, quiet: bool) -> None:
    """Run convergence ladders of CONFIG: answers (M_lr/M_T, N_lr, peak pressures at fixed depths) against
    cost (wall seconds, cell-updates, particle-steps), with a Richardson estimate of the converged value."""
    from .convergence import LadderError, format_table, parse_floats, parse_vary, run_ladders, window_times

    _setup_logging(verbose, quiet)
    config, _ = _load_or_exit(config_path)
    if not tolerance > 0:
        click.echo(f"--tolerance: must be > 0 (got {tolerance})", err=True)
        sys.exit(2)
    if workers is not None and workers < 1:
        click.echo(f"--workers: must be >= 1 (got {workers})", err=True)
        sys.exit(2)
    execution = {"backend": "dask" if scheduler else backend, "scheduler": scheduler, "workers": workers}
    out = Path(out_dir or Path("runs") / f"{config.name}-convergence")
    try:
        ladders = parse_vary(varies)
        depth_values = parse_floats(depths, "--depths")
        times = parse_floats(handoff_times, "--handoff-times") if handoff_times is not None else None
        if handoff_times is not None and single_handoff:
            raise LadderError(["--single-handoff: not with --handoff-times"])
        if times is None and not single_handoff and config.handoff.window:
            times = window_times(config.handoff.window, ladders)
        result = run_ladders(config_path, ladders, out, depths=depth_values, tolerance=tolerance,
                             execution={k: v for k, v in execution.items() if v is not None},
                             show_progress=not quiet, handoff_times=times, seeds=seeds,
                             reuse_runs=list(reuse_hydro))
    except LadderError as exc:
        for message in exc.messages:
            click.echo(message, err=True)
        sys.exit(2)
    except RunDirError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    for line in format_table(result, depth_values, tolerance):
        click.echo(line)
    click.echo(f"wrote {', '.join(str(p) for p in result['files'])}")
    failed = [r for r in result["rungs"] if r.status != "complete"]
    for rung in failed:
        click.echo(f"rung {rung.ladder}={rung.value} failed: {rung.error}", err=True)
    if failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
