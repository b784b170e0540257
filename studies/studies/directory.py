"""What a run_trials directory holds: a campaign, a study or a re-run, each marked by a file of
its own (its plan, its state, its world), so that a run takes only a directory of its own kind
and never writes its trials over another's."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

CAMPAIGN, STUDY, RERUN = 'campaign', 'study', 're-run'
CAMPAIGN_FILE = 'campaign.json'     # a campaign's plan (studies.campaign)
STUDY_STATE = 'study.json'          # a study's hash and answer (studies.study)
STUDY_COPY = 'study.yaml'           # the study file, as it was given
ORIGINAL_WORLD = 'original_world.yaml'   # a re-run's world (studies.rerun)
MARKS = {CAMPAIGN: CAMPAIGN_FILE, STUDY: STUDY_STATE, RERUN: ORIGINAL_WORLD}
UNMARKED = 'trials'                 # trial directories, without a mark of any kind


class DirectoryError(ValueError):
    """A directory that holds another kind of run; the message is the line to print."""


def holds(out: Path) -> Optional[str]:
    """The kind of run ``out`` holds (CAMPAIGN, STUDY, RERUN), UNMARKED for trials without a
    mark, or None when it holds nothing of a run."""
    kinds = [k for k, name in MARKS.items()
             if (out / name).exists() or (out / name).is_symlink()]
    if len(kinds) > 1:
        raise DirectoryError(f'{out} holds both a {kinds[0]} ({MARKS[kinds[0]]}) and a '
                             f'{kinds[1]} ({MARKS[kinds[1]]}): give another --out')
    if kinds:
        return kinds[0]
    return UNMARKED if any(out.glob('trial_*')) else None


def how_to_resume(kind: str, out: Path) -> str:
    """The command that goes on with a run of ``kind`` in ``out``, in words."""
    if kind == CAMPAIGN:
        return f'go on with it: run_trials --resume {out}'
    if kind == STUDY:
        return f'go on with it: run_trials --study {out / STUDY_COPY} --resume {out}'
    return 'give another --out'


def claim(out: Path, kind: str, resume: bool) -> None:
    """``out`` may take a run of ``kind``: a new one (``resume`` False) where it holds no run,
    or the same kind's (``resume``); DirectoryError otherwise."""
    held = holds(out)
    if held == UNMARKED:
        raise DirectoryError(f'{out} holds trials of no campaign or study (no {CAMPAIGN_FILE} '
                             f'or {STUDY_STATE}): give another --out')
    if resume:
        if held == kind:
            return
        if held is None:
            raise DirectoryError(f'{out} holds no {kind} (no {MARKS[kind]}): nothing to '
                                 f'resume; start one with --out {out}')
        raise DirectoryError(f'{out} holds a {held} ({MARKS[held]}), not a {kind}: '
                             f'{how_to_resume(held, out)}')
    if held is None:
        return
    if held == kind and kind != RERUN:
        raise DirectoryError(f'{out} holds a {kind} already ({MARKS[kind]}): go on with '
                             f'--resume {out}, or give another --out')
    raise DirectoryError(f'{out} holds a {held} ({MARKS[held]}): give another --out')
