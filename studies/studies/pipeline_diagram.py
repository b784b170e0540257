"""The pipeline's two machines as state diagrams, from their transition tables (no ROS).

``pipeline_diagram`` prints them as Mermaid ``stateDiagram-v2`` blocks, the form
docs/pipeline.md shows (GitHub draws them); ``--check FILE`` says whether FILE holds them as
printed now (the docs are generated, never drawn by hand)."""
from __future__ import annotations

import argparse
import sys
from enum import Enum
from pathlib import Path
from typing import List, Optional, Sequence, Type

from coordinator.pipeline.loader import LOADER_TRANSITIONS
from coordinator.pipeline.machine import Transitions
from coordinator.pipeline.model import LoaderState, TransportState
from coordinator.pipeline.transport import TRANSPORT_TRANSITIONS

BEGIN = '<!-- pipeline_diagram: begin (generated; do not edit) -->'
END = '<!-- pipeline_diagram: end -->'
MACHINES = (('loader (any arm; the paper\'s Zu 12)', LoaderState, LOADER_TRANSITIONS,
             LoaderState.START),
            ('transport (each youBot)', TransportState, TRANSPORT_TRANSITIONS,
             TransportState.WAIT_LOAD))


def mermaid(title: str, states: Type[Enum], table: Transitions, initial: Enum) -> List[str]:
    """One machine's diagram: its initial state, every transition of its table (in the
    states' order), and its final states (those with no way out)."""
    lines = ['```mermaid', 'stateDiagram-v2', f'    %% {title}', f'    [*] --> {initial.value}']
    for state in states:
        for to in sorted(table[state], key=lambda s: list(states).index(s)):
            lines.append(f'    {state.value} --> {to.value}')
        if not table[state]:
            lines.append(f'    {state.value} --> [*]')
    return lines + ['```']


def diagrams() -> str:
    """Both machines' diagrams, between the markers docs/pipeline.md keeps them in."""
    lines = [BEGIN]
    for title, states, table, initial in MACHINES:
        lines += ['', f'The {title}:', ''] + mermaid(title, states, table, initial)
    return '\n'.join(lines + ['', END]) + '\n'


def in_file(path: Path) -> Optional[str]:
    """What ``path`` holds between the markers (None: no markers)."""
    text = path.read_text()
    if BEGIN not in text or END not in text:
        return None
    start = text.index(BEGIN)
    return text[start:text.index(END, start) + len(END)] + '\n'


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='pipeline_diagram', description=__doc__.split('\n')[0])
    parser.add_argument('--check', type=Path, metavar='FILE',
                        help='exit 1 unless FILE holds the diagrams as printed now')
    args = parser.parse_args(argv)
    if args.check is None:
        sys.stdout.write(diagrams())
        return 0
    held = in_file(args.check)
    if held != diagrams():
        print(f'pipeline_diagram: {args.check} does not hold the diagrams of the transition '
              'tables as they are: paste `pipeline_diagram` there', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
