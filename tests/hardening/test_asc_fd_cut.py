"""CAN FD lines of an ASC log cut short are skipped lines with warnings, like classic ones
(issue 28, "ASC CAN FD truncation"), through ``gyrostand replay``: 40 ``CANFD`` frame lines
cut anywhere from their time's second character to before their last data byte are 40 skipped
lines, and every other frame is read (before: a line cut inside ``<t> CANFD <ch> Rx <id>
<brs> <esi> <dlc> <len>`` vanished without a word: 6 of 20 in one trial)."""

from __future__ import annotations

import json
import random

import can

from gyrostand.cli import main as cli_main

from .procs import simulated_session


def test_cut_canfd_lines_are_skipped_lines(tmp_path, capsys):
    cfg_path, frames = simulated_session(tmp_path, duration=60.0)
    log = tmp_path / "fd.asc"
    with can.Logger(str(log)) as lg:
        for f in frames:
            lg.on_message_received(can.Message(
                timestamp=f.timestamp, arbitration_id=f.arbitration_id, is_fd=True,
                is_extended_id=f.is_extended_id, data=bytes(f.data)))
    lines = log.read_text().splitlines(keepends=True)
    body = [i for i, ln in enumerate(lines) if " CANFD " in ln]
    assert len(body) == len(frames)
    rng = random.Random(28)
    for i in sorted(rng.sample(body, 40)):
        ln = lines[i]
        first = len(ln) - len(ln.lstrip())
        f = frames[body.index(i)]
        data = " ".join(f"{b:02X}" for b in f.data)
        end = ln.index(data, ln.index(" CANFD ")) + len(data) - 2  # before the last byte
        lines[i] = ln[:rng.randint(first + 1, end)] + "\n"
    log.write_text("".join(lines))
    rc = cli_main(["replay", str(cfg_path), str(log), "--out", str(tmp_path / "runs"),
                   "--json", "--reader", "inline"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    stats = json.loads(out.out)["stats"]
    assert stats["log"]["lines_skipped"] == 40
    assert stats["decoder"]["received"] == len(frames) - 40
    assert all("cut short" in n for n in stats["log"]["notes"][:5])
