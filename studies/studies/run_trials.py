"""Run the pipeline scenario N times with varied seeds and write the paper's Table 2 for them.

Each trial is its own process group (sim_node in lock-step, vision_node, two kinematics_nodes,
coordinator_node) on its own ROS_DOMAIN_ID, so trials run side by side (``--parallel``) or on
several machines (``--first-trial``/``--domain-base`` split the seeds). The scenario seed sets
the material order, spacing and lateral placement; the belt speed is drawn per trial from
``--belt-speed``. Writes trials.csv, report.md and PNG plots into ``--out``.
"""
from __future__ import annotations

import argparse
import math
import os
import shlex
import signal
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, NoReturn, Optional, Sequence

from ros_common.outputs import OutputError, check_output_dir, make_dir
from studies import directory
from studies.campaign import (
    PLAN_DEFAULTS,
    CampaignError,
    Reuse,
    campaign_lock,
    check_plan,
    finished_result,
    read_campaign,
    rebuild,
    write_campaign,
    write_csv,
)
from studies.directory import CAMPAIGN_FILE
from studies.plan import check_sweep_worlds, check_world, plan_of
from studies.pool import LocalPool, Pool, campaign_progress
from studies.progress import (
    CampaignBar,
    progress_line,
    running_figures,
)
from studies.rerun import Rerun, RerunError, figures, first_parting
from studies.rerun import check as check_rerun
from studies.trial_graph import pipeline_graph
from studies.trial_process import (
    INTERRUPTED,
    MAX_DOMAIN,
    PlanItem,
    stop_all,
)
from trial_record.result import (
    TrialResult,
    code_version,
)
from world_description import PIPELINE_CELL

PROGRESS_PERIOD_S = 10.0     # wall seconds between two progress lines


def _terminated(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt   # SIGTERM stops the running trials as Ctrl-C does


def main(argv: Optional[Sequence[str]] = None) -> int:
    signal.signal(signal.SIGTERM, _terminated)
    INTERRUPTED.clear()
    try:
        return _main(argv)
    except KeyboardInterrupt:       # (before the campaign started, or while it wrote up or
        stop_all(at_once=True)      # stopped its trials: a second Ctrl-C)
        print('[trials] interrupted', flush=True)
        return 130


def _given_plan(args: argparse.Namespace) -> Dict[str, Any]:
    """The plan's options given on the command line, checked (CampaignError)."""
    return check_plan({k: (list(v) if isinstance(v, (tuple, list)) else v)
                       for k in PLAN_DEFAULTS if (v := getattr(args, k)) is not None},
                      'the command line')


def _plan_options(args: argparse.Namespace, given: Dict[str, Any]) -> Dict[str, Any]:
    """The plan: as given, else as the campaign being resumed had it, else the defaults; every
    option checked (CampaignError)."""
    stored: Dict[str, Any] = {}
    if args.resume is not None:
        stored = read_campaign(args.out) or {}
        for k, v in given.items():
            if k in stored and stored[k] != v:
                raise CampaignError(f'--{k.replace("_", "-")} {v} differs from the campaign '
                                    f'being resumed ({stored[k]}, in {args.out / CAMPAIGN_FILE})')
    return check_plan({**PLAN_DEFAULTS, **stored, **given}, 'the plan')


class _Parser(argparse.ArgumentParser):
    """A bad option is one line (``--help`` lists them all), not the usage of 25 options."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f'{self.prog}: error: {message} (run_trials --help lists the options)\n')


def _parser() -> '_Parser':
    parser = _Parser(prog='run_trials', description=__doc__.splitlines()[0])
    parser.add_argument('--trials', type=int, default=None, help='trials in the plan (10)')
    parser.add_argument('--parallel', type=int, default=None,
                        help='trials at once (each a process group on its own DDS domain); '
                             '1, or with --ray as many as the cluster has CPUs for')
    parser.add_argument('--seed0', type=int, default=None, help='seeds the trial plan (2026)')
    parser.add_argument('--seeds', type=int, nargs='+', default=None,
                        help='run exactly these scenario seeds (instead of --trials drawn ones)')
    parser.add_argument('--first-trial', type=int, default=None,
                        help='skip this many trials of the plan (split a plan over machines)')
    parser.add_argument('--belt-speed', type=float, nargs=2, default=None,
                        metavar=('LO', 'HI'), help='belt speed range [m/s] (0.10 0.16)')
    parser.add_argument('--sweep', action='append', default=None, metavar='NAME=VALUES',
                        help='run the plan at each value of a parameter: belt_speed or a '
                             'number of the world file by its path (perturbations.camera.'
                             'pixel_noise); VALUES START:STOP:STEP or V1,V2,...; twice: a grid '
                             '(docs/studies.md)')
    parser.add_argument('--trials-per-point', type=int, default=None,
                        help='with --sweep: trials at each point (--trials), the same seeds '
                             'at every point')
    parser.add_argument('--break-below', type=float, default=None,
                        help='with --sweep: the report names the first point where a rate '
                             'falls below this (0.9)')
    parser.add_argument('--domain-base', type=int, default=int(os.environ.get(
        'TRIALS_DOMAIN_BASE', '200')), help='a trial takes the first DDS domain from here on '
        'that no other trial on its machine holds (200 on: apart from the test suite, 1-159, '
        'and the demos, 160-199)')
    parser.add_argument('--ray', nargs='?', const='', default=None, metavar='ADDRESS',
                        help='run each trial as a task on a Ray cluster: ADDRESS as ray.init '
                             'takes it (auto, HOST:6379, ray://HOST:10001); without it, the '
                             'cluster of RAY_ADDRESS or one started on this machine')
    parser.add_argument('--cpus-per-trial', type=float, default=None,
                        help='with --ray: the CPUs a trial takes on its node (1)')
    parser.add_argument('--collect-bags', action='store_true',
                        help='with --ray --record: copy each bag to --out (else it stays on '
                             'the worker that recorded it, named in the result)')
    parser.add_argument('--world', default=None,
                        help='the cell\'s world file, for sim_node and the coordinator '
                             f'({PIPELINE_CELL})')
    parser.add_argument('--time-step', type=float, default=None,
                        help='the physics step [s] (1/240); 1/120 runs a trial in about 30 %% '
                             'less CPU (docs/benchmarks.md, "The physics step")')
    parser.add_argument('--wall-timeout', type=float, default=900.0)
    parser.add_argument('--record', action='store_true', help='record a bag per trial')
    parser.add_argument('--out', type=Path, default=None,
                        help='the campaign directory (runs/trials-<date>-<time>)')
    parser.add_argument('--progress-period', type=float, default=PROGRESS_PERIOD_S,
                        help='wall seconds between progress updates')
    parser.add_argument('--bar', choices=('auto', 'on', 'off'), default='auto',
                        help='a live progress bar (auto: on a terminal; else progress lines)')
    parser.add_argument('--show-graph', action='store_true',
                        help="print the processes of the plan's first trial as command lines "
                             '(what to start by hand, each on the same ROS_DOMAIN_ID), and '
                             'exit')
    parser.add_argument('--report-only', action='store_true',
                        help='rebuild trials.csv and the report from the results in --out')
    parser.add_argument('--rerun', default=None, metavar='RUN',
                        help='run a recorded trial again (its result.json, trial directory, '
                             'or a run directory with one trial, such as make demo\'s), as it '
                             'was or changed by --set, and say what came out different')
    parser.add_argument('--set', action='append', default=None, metavar='NAME=VALUE',
                        help='with --rerun: change belt_speed or a number of the world file '
                             '(by its path) for the re-run')
    parser.add_argument('--study', default=None, metavar='FILE',
                        help='run a study (a search under a constraint, or a screening of '
                             'factors) described by FILE into --out (docs/studies.md); '
                             '--resume DIR goes on with a stopped one')
    parser.add_argument('--resume', nargs='?', const='', default=None, metavar='DIR',
                        help='go on with an interrupted campaign in DIR (or --out), with its '
                             'plan (with --study: a study): skip each trial whose result is '
                             'there and ran what the plan asks (it ran to an outcome, with the '
                             'same seed, belt speed, setting, world, physics step, and code: '
                             'the same commit, with no uncommitted changes)')
    return parser


def _main(argv: Optional[Sequence[str]]) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    _check_arguments(args, parser)
    if args.rerun is not None:
        return _rerun(args)
    if args.study is not None:
        return _study(args, parser)
    _campaign_directory(args, parser)
    try:
        given = _given_plan(args)
        if args.show_graph:
            return _show_graph({**PLAN_DEFAULTS, **given})
        if args.resume is None and not args.report_only:
            # (Before any file: a refused plan leaves no campaign directory behind.)
            check_world(given.get('world', PLAN_DEFAULTS['world']))
            check_sweep_worlds({**PLAN_DEFAULTS, **given})
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CampaignError(f'--out {args.out}: {exc.strerror or exc}') from None
        with campaign_lock(args.out):
            if args.report_only:
                if directory.holds(args.out) == directory.STUDY:
                    raise CampaignError(f'{args.out} holds a study: its report is '
                                        f'{args.out / "study.md"}; '
                                        + directory.how_to_resume(directory.STUDY, args.out))
                return rebuild(args.out)
            directory.claim(args.out, directory.CAMPAIGN, args.resume is not None)
            return _campaign(args, given)
    except (CampaignError, directory.DirectoryError) as exc:
        print(f'run_trials: error: {exc}', file=sys.stderr, flush=True)
        return 2


def _rerun(args: argparse.Namespace) -> int:
    """run_trials --rerun RUN [--set NAME=VALUE ...]: the trial again, into --out."""
    out = args.out or Path('runs') / time.strftime('rerun-%Y%m%d-%H%M%S')
    try:
        check_output_dir(out, '--out')
        rerun = check_rerun(Path(args.rerun), args.set or [])
        make_dir(out, '--out')
        with campaign_lock(out):
            directory.claim(out, directory.RERUN, resume=False)
            return _run_again(rerun.written_to(out), out, args)
    except (RerunError, CampaignError, OutputError, directory.DirectoryError) as exc:
        print(f'run_trials: error: {exc}', file=sys.stderr, flush=True)
        return 2


def _run_again(rerun: Rerun, out: Path, args: argparse.Namespace) -> int:
    original, code = rerun.original, code_version()
    changed = ', '.join(f'{k} {v:g}' for k, v in rerun.changes.items()) or 'nothing changed'
    print(f'[rerun] trial {original.trial} of {rerun.source} again: seed {rerun.seed}, belt '
          f'{rerun.belt_speed:g} m/s, step {rerun.time_step:g} s; {changed}', flush=True)
    if original.run.code != code:
        print(f'[rerun] note: the original ran code {original.run.code or "unknown"}, this is '
              f'{code}: a difference may come from the code', flush=True)
    item = PlanItem(trial=original.trial or 0, seed=rerun.seed, belt_speed=rerun.belt_speed)
    if rerun.changes:
        item['parameters'] = dict(rerun.changes)
    pool = LocalPool(1, out, {'wall_timeout': args.wall_timeout, 'record': args.record,
                              'code': code, 'world': rerun.world, 'time_step': rerun.time_step,
                              'domain_base': args.domain_base})
    results: List[TrialResult] = []
    if _run_plan(pool, [item], results, 1, args):
        print(f'[rerun] interrupted; nothing to compare ({out})', flush=True)
        return 130
    again = results[0]
    write_csv(results, out / 'trials.csv')
    if not again.ran:
        # (Nothing to compare: the exit code says the re-run failed, whatever was asked.)
        print(f'[rerun] the re-run did not run to its end: {again.status}: '
              f'{again.message or "no message"} ({out})', flush=True)
        return 1
    from studies.report import write_report
    write_report(results, out, {'note': f'Trial {original.trial} of {rerun.source} run again; '
                                        f'{changed}.', 'world': rerun.world})
    differ = again.differences(original)
    for label, before, after in figures(original, again):
        print(f'[rerun]   {label:>16}: {before:>12} -> {after}', flush=True)
    if not differ:
        print(f'[rerun] the same run as the original: the same {len(again.events)} events, '
              'materials and figures', flush=True)
        return 0
    print(f'[rerun] differs from the original in {", ".join(differ)}; first: '
          f'{first_parting(original, again) or "the same events"}', flush=True)
    return 1 if not rerun.changes else 0


def _study(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """run_trials --study FILE [--out DIR | --resume DIR]: the study's trials and answer."""
    from studies.study import StudyError, check, claim, run_study
    plan = [k for k in PLAN_DEFAULTS if k != 'time_step' and getattr(args, k) is not None]
    if plan or args.report_only or args.show_graph:
        parser.error('--study takes its plan from the study file: no '
                     f'{", ".join("--" + k.replace("_", "-") for k in plan) or "--report-only"}')
    _campaign_directory(args, parser)
    try:
        if args.time_step is not None:
            check_plan({'time_step': args.time_step}, 'the command line')
        study, path = check(args.study)
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CampaignError(f'--out {args.out}: {exc.strerror or exc}') from None
        with campaign_lock(args.out):
            step = claim(study, path, args.out, args.resume is not None, args.time_step)
            code = code_version()
            trial_options = {'wall_timeout': args.wall_timeout, 'record': args.record,
                             'code': code, 'world': study.world, 'time_step': step,
                             'domain_base': args.domain_base}
            pool = _pool(args, trial_options)
            if pool is None:
                return 2
            return run_study(study, pool, args.out, Reuse(study.world, step, code),
                             args.progress_period)
    except (StudyError, CampaignError) as exc:
        print(f'run_trials: error: {exc}', file=sys.stderr, flush=True)
        return 2


def _campaign_directory(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """``args.out``: the directory named by --resume or --out, or a new one under runs/."""
    if args.resume:
        if args.out is not None and args.out != Path(args.resume):
            parser.error(f'--resume {args.resume} and --out {args.out} name two directories')
        args.out = Path(args.resume)
    if args.out is None:
        if args.resume is not None or args.report_only:
            parser.error('name the campaign directory: --resume DIR, or --out DIR')
        args.out = Path('runs') / time.strftime(
            ('study' if args.study is not None else 'trials') + '-%Y%m%d-%H%M%S')
    if (args.resume is not None or args.report_only) and not args.out.is_dir():
        parser.error(f'{args.out} is not a campaign directory (nothing to '
                     f'{"resume" if args.resume is not None else "report"})')


def _check_arguments(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """The options that are not the plan's (check_plan checks those), each in its range."""
    if args.set is not None and args.rerun is None:
        parser.error('--set goes with --rerun (a sweep: --sweep)')
    if args.rerun is not None:
        plan = [k for k in PLAN_DEFAULTS if getattr(args, k) is not None]
        if plan or args.resume is not None or args.report_only or args.ray is not None:
            parser.error('--rerun takes the trial as it was: no plan options '
                         f'({", ".join(plan) or "--resume, --report-only, --ray"}), only --set')
    if args.parallel is not None and args.parallel < 1:
        parser.error('--parallel must be >= 1')
    if not (args.wall_timeout > 0.0 and math.isfinite(args.wall_timeout)):
        parser.error('--wall-timeout must be a number of seconds > 0')
    if not (args.progress_period > 0.0 and math.isfinite(args.progress_period)):
        parser.error('--progress-period must be a number of seconds > 0')
    if not 0 <= args.domain_base <= MAX_DOMAIN:
        parser.error(f'--domain-base must be a DDS domain, 0-{MAX_DOMAIN}')
    if args.ray is None and (args.domain_base + (args.parallel or 1) - 1 > MAX_DOMAIN):
        parser.error(f'--domain-base + --parallel must stay within DDS domain {MAX_DOMAIN}')
    if args.ray is None and (args.collect_bags or args.cpus_per_trial is not None):
        parser.error('--collect-bags and --cpus-per-trial go with --ray')
    if args.collect_bags and not args.record:
        parser.error('--collect-bags needs --record')
    if args.cpus_per_trial is not None and not (args.cpus_per_trial > 0
                                                 and math.isfinite(args.cpus_per_trial)):
        parser.error('--cpus-per-trial must be > 0')


def _show_graph(opts: Dict[str, Any]) -> int:
    check_world(opts['world'])
    first = plan_of(opts)[0]
    print(f"# trial {first['trial']}: seed {first['seed']}, belt {first['belt_speed']} m/s")
    for node in pipeline_graph(first['seed'], first['belt_speed'], world=opts['world'],
                               time_step=opts['time_step']):
        print(shlex.join(node.command()))
    return 0


def _pool(args: argparse.Namespace, trial_options: Dict[str, Any]) -> Optional[Pool]:
    """The pool the campaign's trials run in: local processes, or a Ray cluster (None, and
    why on stderr, if it cannot be used)."""
    if args.ray is None:
        return LocalPool(args.parallel or 1, args.out, trial_options)
    from studies.ray_pool import RayPool  # Ray is imported only with --ray
    try:
        return RayPool(args.ray or None, args.out, trial_options, args.cpus_per_trial,
                       args.collect_bags, args.parallel)
    except Exception as exc:                     # (Ray's errors have no common base)
        print(f'[trials] cannot use the Ray cluster {args.ray or "(local)"}: {exc}',
              file=sys.stderr, flush=True)
        return None


def _finished_line(r: TrialResult, done: int, total: int, elapsed: float) -> str:
    """The line that says a trial finished."""
    where = f' on {r.run.node}' if r.run.node else ''
    handling = (f'{r.handling_success_rate:.0%}' if math.isfinite(r.handling_success_rate)
                else '-')
    point = ''.join(f', {k} {v:g}' for k, v in r.parameters.items() if k != 'belt_speed')
    return (f'[trials] {done}/{total} trial {r.trial} seed {r.scenario_seed} belt '
            f'{r.belt_speed:.3f}{point}: {r.status}, {r.completion_time:.1f} s sim, '
            f'handling {handling}, wall {r.run.wall_time:.0f} s{where} (elapsed {elapsed:.0f} s)')


def _campaign(args: argparse.Namespace, given: Dict[str, Any]) -> int:
    """Run the plan into ``args.out`` (held by this runner)."""
    opts = _plan_options(args, given)
    if args.resume is not None:
        check_world(opts['world'])
        check_sweep_worlds(opts)
    lo, hi = opts['belt_speed']
    plan = plan_of(opts)
    results: List[TrialResult] = []
    code = code_version()
    if args.resume is not None:
        reuse = Reuse(opts['world'], opts['time_step'], code)
        done = [r for r in (finished_result(args.out, item, reuse) for item in plan)
                if r is not None]
        plan = [item for item in plan if item['trial'] not in {r.trial for r in done}]
        results.extend(done)
        print(f'[trials] resuming: {len(done)} trials of the plan already in {args.out} '
              f'ran as the plan runs them (code {code})', flush=True)
    write_campaign(args.out, opts, code)
    trial_options = {'wall_timeout': args.wall_timeout, 'record': args.record, 'code': code,
                     'world': opts['world'], 'time_step': opts['time_step'],
                     'domain_base': args.domain_base}
    pool = _pool(args, trial_options)
    if pool is None:
        return 2
    print(f'[trials] {len(plan)} trials, {pool.describe()}, into {args.out}', flush=True)
    total = len(plan) + len(results)
    started = time.monotonic()
    interrupted = _run_plan(pool, list(plan), results, total, args)
    write_csv(results, args.out / 'trials.csv')
    from studies.report import write_report
    setup = {'seed0': opts['seed0'], 'belt_speed': (lo, hi), 'parallel': pool.capacity,
             'wall_time': time.monotonic() - started, 'code': code, 'world': opts['world'],
             'break_below': opts['break_below'], 'sweep': opts['sweep']}
    if interrupted:
        setup['note'] = (f'Interrupted: {len(results)} of the {total} trials of the plan '
                         f'finished (plan seed {opts["seed0"]}, belt {lo}-{hi} m/s); '
                         f'`run_trials --resume {args.out}` runs the others.')
    report = write_report(results, args.out, setup) if results else None
    print(f'[trials] CSV {args.out / "trials.csv"}, '
          + (f'report {report}' if report else 'no report (no trial finished)'), flush=True)
    if interrupted:
        print(f'[trials] interrupted: running trials stopped; {len(results)} finished'
              + (', in the CSV and report' if results else '')
              + f'; run_trials --resume {args.out} goes on', flush=True)
        return 130
    return 0 if all(r.status == 'completed' for r in results) else 1


def _run_plan(pool: Pool, pending: List[PlanItem], results: List[TrialResult], total: int,
              args: argparse.Namespace) -> bool:
    """Run the pending trials on the pool, each result added to ``results`` (and the CSV) as it
    comes in; whether the user stopped the campaign."""
    # On a terminal a live bar; in a log, a line now and then.
    bar = (CampaignBar(total, len(results), sys.stderr)
           if args.bar == 'on' or args.bar == 'auto' and sys.stderr.isatty() else None)
    say = bar.write if bar is not None else (lambda line: print(line, flush=True))
    started = time.monotonic()
    interrupted = False
    try:
        while pending and pool.has_room():
            pool.submit(pending.pop(0))
        while pool.busy():
            r = pool.wait(args.progress_period)
            if r is None:
                states, eta = campaign_progress(pool, results, len(pending))
                if bar is not None:
                    bar.update(results, states, eta)
                else:
                    say(progress_line(len(results), total, states, eta) + '; '
                        + running_figures(results))
                continue
            results.append(r)
            write_csv(results, args.out / 'trials.csv')      # partial results survive
            say(_finished_line(r, len(results), total, time.monotonic() - started))
            if bar is not None:
                bar.update(results, *campaign_progress(pool, results, len(pending)), finished=1)
            while pending and pool.has_room():
                pool.submit(pending.pop(0))
    except KeyboardInterrupt:
        # Stopped by the user (Ctrl-C, SIGTERM): the running trials are stopped (within
        # INTERRUPT_GRACE); what finished goes into the CSV and the report.
        pool.stop()
        interrupted = True
    finally:
        pool.close()
        if bar is not None:
            bar.close()
    if interrupted:
        # (Trials that ended while the campaign stopped: their results are in their
        # directories, and so in the CSV.)
        results.extend(r for r in pool.drain() if r.status != 'interrupted')
    return interrupted


if __name__ == '__main__':
    sys.exit(main())
