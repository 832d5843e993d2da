"""A generated plugin term (``gyrostand term new``) used as a user uses it: registered as a
session file's ``plugins:`` would register it, then the real command line in a fresh
interpreter — ``fit RUN --add NAME``, then ``diagnose RUN`` on the bigger model."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any


def fit_and_diagnose(pkg: Path, csv: Path, name: str, cwd: Path | None = None
                     ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The JSON of ``fit CSV --add NAME`` and of the ``diagnose CSV`` after it, with the
    package folder ``pkg`` (its module ``gyrostand_NAME``) on the path."""
    script = (
        "import sys, json, io, contextlib\n"
        "from gyrostand.plugins import load_modules\n"
        f"load_modules(['gyrostand_{name}'])\n"
        "from gyrostand.cli import main\n"
        f"assert main(['fit', {str(csv)!r}, '--add', {name!r}, '--format', 'json']) == 0\n"
        "buf = io.StringIO()\n"
        "with contextlib.redirect_stdout(buf):\n"
        f"    assert main(['diagnose', {str(csv)!r}, '--format', 'json', '-q']) == 0\n"
        "print('DIAGNOSIS' + buf.getvalue())\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(pkg), os.environ.get(
        "PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       timeout=600, env=env, cwd=cwd)
    assert r.returncode == 0, r.stderr[-3000:]
    fit_json, diag_json = r.stdout.split("DIAGNOSIS")
    return json.loads(fit_json), json.loads(diag_json)
