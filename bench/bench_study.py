"""A search's answer and cost against a dense sweep of the same cell (issue 51).

Reads a finished study of one factor under a constraint (``run_trials --study``'s directory)
and a sweep of that factor (``run_trials --sweep``'s directory, the same world and scenario
seeds, ``trials_per_setting`` trials a point); judges each point of the sweep by the study's own
constraint, on all its trials; and prints what the sweep says (the best point that meets it),
what the search said, how far apart they are, and the trials each took. With ``--at-least P``
the sweep is judged at another bound too (the same trials: the sweep's answer to the question
asked with P), and the search is replayed at that bound on the sweep's own trials (its settings
on the sweep's grid: a lock-step trial at the same seed and speed is the same run, so a search
run there would get these results), to set its answer and its trials beside the sweep's.
Writes JSON to bench/results/study.json.

    python bench/bench_study.py --sweep docs/studies/belt-speed-dense --study runs/belt-study
"""
import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, Dict, List, Optional

from studies.campaign import trial_results
from studies.study import STUDY_COPY, STUDY_STATE
from studies.study_file import Constraint, load_study
from studies.study_search import Searcher, decide
from trial_record.result import TrialResult

HERE = Path(__file__).resolve().parent


def sweep_answer(results: List[TrialResult], name: str, c: Constraint, per: int,
                 maximise: bool) -> Dict[str, Any]:
    """The sweep's points judged by ``c`` on their first ``per`` trials: each point's counts and
    verdict, and the best point that meets it."""
    points: Dict[float, List[TrialResult]] = {}
    for r in sorted(results, key=lambda r: r.trial or 0):
        value = r.parameters.get(name, r.belt_speed if name == 'belt_speed' else math.nan)
        points.setdefault(float(value), []).append(r)
    rows, met = [], []
    from studies.study_file import response_of
    for value in sorted(points):
        trials = points[value][:per]
        s = sum(response_of(r, c.response)[0] for r in trials)
        n = sum(response_of(r, c.response)[1] for r in trials)
        verdict, how = decide(s, n, len(trials), per, c)
        rows.append({'value': value, 'trials': len(trials), 'successes': s, 'n': n,
                     'met': bool(verdict), 'how': how})
        if verdict:
            met.append(value)
    best: Optional[float] = (max(met) if maximise else min(met)) if met else None
    return {'points': rows, 'answer': best, 'trials': sum(r['trials'] for r in rows)}


def replay(study: Any, results: List[TrialResult], at_least: float) -> Dict[str, Any]:
    """The study's search at ``at_least``, its trials taken from the sweep's (KeyError: a
    setting off the sweep's grid or seeds)."""
    by_run = {(r.scenario_seed, round(r.belt_speed, 6)): r for r in results}
    spec = study.search
    asked = replace(study, search=replace(spec, constraint=replace(spec.constraint,
                                                                     at_least=at_least)))

    def lookup(items: List[Any]) -> List[TrialResult]:
        return [by_run[(i['seed'], round(i['belt_speed'], 6))] for i in items]
    answer = Searcher(asked, lookup, 2, lambda line: None).run()
    name = study.factors[0].name
    return {'answer': answer.best.values[name] if answer.best else None,
            'trials': answer.trials, 'settled': answer.settled, 'summary': answer.summary}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sweep', type=Path, required=True)
    parser.add_argument('--study', type=Path, required=True)
    parser.add_argument('--at-least', type=float, nargs='*', default=[])
    args = parser.parse_args()
    study = load_study(args.study / STUDY_COPY)
    spec = study.search
    if spec is None or spec.constraint is None or len(study.factors) != 1:
        print('bench_study: the study must be a search of one factor under a constraint',
              file=sys.stderr)
        return 2
    name = study.factors[0].name
    results, problems = trial_results(args.sweep)
    if problems:
        print('\n'.join(problems), file=sys.stderr)
        return 2
    state = json.loads((args.study / STUDY_STATE).read_text())
    answer = state.get('answer') or {}
    best = answer.get('best')
    found = best['values'][name] if best else None
    judged = sweep_answer(results, name, spec.constraint, spec.trials_per_setting,
                          spec.maximise)
    apart = (abs(found - judged['answer']) if found is not None
             and judged['answer'] is not None else None)
    print(f'[bench] the question: {answer.get("summary", "")}')
    # (The study's trials at the sweep's seeds and speeds are the same lock-step runs.)
    own, _ = trial_results(args.study)
    swept = {(r.scenario_seed, round(r.belt_speed, 6)): r for r in results}
    pairs = [(r, swept[(r.scenario_seed, round(r.belt_speed, 6))]) for r in own
             if (r.scenario_seed, round(r.belt_speed, 6)) in swept]
    same = sum(a.handled_verified == b.handled_verified and a.events == b.events
               for a, b in pairs)
    print(f'[bench] the study\'s trials that the sweep ran too: {same} of {len(pairs)} the same '
          'run (the same events and materials handled)')
    for row in judged['points']:
        print(f"[bench]   sweep {name} {row['value']:g}: {row['successes']:g}/{row['n']:g} "
              f"in {row['trials']} trials: {'met' if row['met'] else 'failed'} ({row['how']})")
    print(f"[bench] the sweep says {judged['answer']} from {judged['trials']} trials; the "
          f"search {found} from {answer.get('trials')} trials "
          f"({answer.get('trials', 0) / max(1, judged['trials']):.0%} of the sweep's)"
          + (f'; {apart:.3f} apart' if apart is not None else
             '; both none' if found is None and judged['answer'] is None else ''))
    other = {}
    for p in args.at_least:
        at = Constraint(spec.constraint.response, p, spec.constraint.confidence)
        dense = sweep_answer(results, name, at, spec.trials_per_setting, spec.maximise)
        try:
            searched = replay(study, results, p)
        except KeyError as exc:
            print(f'[bench] at_least {p:g}: the sweep says {dense["answer"]}; the search asks '
                  f'for a trial the sweep has not run ({exc}): no replay', flush=True)
            other[p] = {'sweep': dense['answer']}
            continue
        other[p] = {'sweep': dense['answer'], 'search': searched}
        print(f"[bench] at_least {p:g}: the sweep says {dense['answer']} from "
              f"{dense['trials']} trials; the search, replayed on them, "
              f"{searched['answer']} from {searched['trials']} trials "
              f"({'settled' if searched['settled'] else 'not settled'})", flush=True)
    out = HERE / 'results' / 'study.json'
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({'study': str(args.study), 'sweep': str(args.sweep),
                               'search': {'answer': found, 'trials': answer.get('trials')},
                               'dense': judged, 'apart': apart,
                               'other_bounds': other}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
