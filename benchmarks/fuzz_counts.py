"""How much the receive-path and command-path property tests try: examples and frames.

Runs the two Hypothesis properties of the hardening suite once each, at their own settings
(``tests/hardening/test_fuzz_receive.py``: 400 examples of arbitrary frames through the
decoding listener and the binner; ``tests/hardening/test_commands.py``: 40 sequences of
command frames through the pipeline), and prints how many examples ran and how many frames
they held: the figures the issue notes quote. The tests themselves assert the properties;
the counting lives here (a test that only prints cannot fail). Then the damage counts of
``benchmarks/damage_counts.py`` (issue 28): frames lost per damaged BLF container, VAL_
codes, unit variants and a signal storm, through ``gyrostand replay``.

Run: ``.venv/bin/python benchmarks/fuzz_counts.py`` (output:
``benchmarks/results/fuzz_counts.txt``)
"""

from __future__ import annotations

import logging
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from tests.hardening import test_commands, test_fuzz_receive  # noqa: E402


class _TmpFactory:
    """What the command property asks pytest's ``tmp_path_factory`` for."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def mktemp(self, name: str) -> Path:
        return Path(tempfile.mkdtemp(prefix=f"{name}-", dir=self.root))


def main() -> None:
    logging.basicConfig(level=logging.ERROR)  # the fuzz's rejections are logged as warnings
    t0 = time.perf_counter()
    test_fuzz_receive.EXAMPLES.update(n=0, frames=0)
    test_fuzz_receive.test_nothing_escapes_and_every_frame_is_accounted_for()
    rx = dict(test_fuzz_receive.EXAMPLES)
    t1 = time.perf_counter()
    test_commands.COUNTS.update(examples=0, command_frames=0)
    with tempfile.TemporaryDirectory() as d:
        test_commands.test_every_command_frame_is_answered_once_and_the_rate_holds(
            tmp_path_factory=_TmpFactory(Path(d)))
    cmd = dict(test_commands.COUNTS)
    t2 = time.perf_counter()
    print(f"receive fuzz: {rx['n']} examples, {rx['frames']} frames ({t1 - t0:.1f} s)")
    print(f"command property: {cmd['examples']} examples, {cmd['command_frames']} command "
          f"frames ({t2 - t1:.1f} s)", flush=True)
    import damage_counts

    damage_counts.main()


if __name__ == "__main__":
    main()
