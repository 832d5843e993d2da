"""The batch commands' C heap (gyrostand.cli.heap): glibc takes the thresholds, the user can
keep glibc's defaults, and the daemon's command is not among those that change it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from gyrostand.cli import heap

CHECK = ("from gyrostand.cli.heap import keep_heap; print(keep_heap())")


def _run(env: dict[str, str]) -> str:
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True,
                         env={**os.environ, **env}, check=True, timeout=120)
    return out.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux") or
                    os.confstr("CS_GNU_LIBC_VERSION") is None, reason="glibc's mallopt")
def test_glibc_takes_the_thresholds() -> None:
    assert _run({"GYROSTAND_HEAP": ""}) == "True"


def test_default_keeps_glibc_defaults() -> None:
    assert _run({"GYROSTAND_HEAP": "default"}) == "False"


def test_only_batch_commands() -> None:
    assert {"diagnose", "identify", "fit"} <= heap.COMMANDS
    assert not {"run", "replay", "batch"} & heap.COMMANDS
    # freed arrays below the mmap threshold are kept at the heap's top, not trimmed at once
    assert heap.TRIM_THRESHOLD >= heap.MMAP_THRESHOLD
