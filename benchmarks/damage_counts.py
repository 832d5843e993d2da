"""Frames lost per damage event, and what codes, units and a storm cost (issue 28).

Through ``gyrostand replay`` (the command line's main entry, array and per-frame paths) on
a 1200-s simulated session (20 drift + 10 temperature frames/s, 36,000 frames in BLF
containers of python-can's default size):

1. **damaged containers**: 4 bytes flipped in container k (each k, and two at once):
   frames lost vs the frames whose objects lie in the damaged container (target: only
   those);
2. **SNA codes**: a fraction p of temperature frames carries a ``VAL_`` code
   (``NotAvailable``/``Error``, inside the DBC range): counted, never binned;
3. **unit variants**: the same raw bits declared K, degK, Kelvin, °F, mK (temperature) or
   rad/s, deg/s, mrad/s (drift): largest |sample difference| vs the degC / deg/h log;
4. **signal storm**: ~300,000 extra frames (16 unknown ids at 8x the stand's rate, and an
   id of the DBC no channel maps) interleaved with the stand's: clean frames lost and
   samples.csv compared byte for byte with the storm-free replay.

Run: ``.venv/bin/python benchmarks/damage_counts.py`` (``fuzz_counts.py`` runs it too);
output in ``benchmarks/results/fuzz_counts.txt``.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import sys
import tempfile
import time
import zlib
from pathlib import Path

import can
import cantools
import yaml
from can.io import blf

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gyrostand.cli import main as cli_main  # noqa: E402
from tests.hardening.procs import DBC, simulated_session  # noqa: E402

TEMP = ' SG_ Temperature : 0|16@1- (0.01,0) [-60|150] "degC" GYROSTAND'
DRIFT = ' SG_ Drift : 0|32@1- (1E-005,0) [-1000|1000] "deg/h" GYROSTAND'
RAD = 1e-5 * math.pi / 180 / 3600
UNITS = {
    "K": (TEMP, ' SG_ Temperature : 0|16@1- (0.01,273.15) [213.15|423.15] "K" GYROSTAND'),
    "degK": (TEMP, ' SG_ Temperature : 0|16@1- (0.01,273.15) [213.15|423.15] "degK" GYROSTAND'),
    "Kelvin": (TEMP, ' SG_ Temperature : 0|16@1- (0.01,273.15) [213|424] "Kelvin" GYROSTAND'),
    "°F": (TEMP, ' SG_ Temperature : 0|16@1- (0.018,32) [-76|302] "°F" GYROSTAND'),
    "mK": (TEMP, ' SG_ Temperature : 0|16@1- (10,273150) [213150|423150] "mK" GYROSTAND'),
    "rad/s": (DRIFT, f' SG_ Drift : 0|32@1- ({RAD!r},0) [-0.005|0.005] "rad/s" GYROSTAND'),
    "deg/s": (DRIFT, ' SG_ Drift : 0|32@1- (2.7777777777777777e-09,0) [-1|1] "deg/s" '
                     'GYROSTAND'),
    "mrad/s": (DRIFT, f' SG_ Drift : 0|32@1- ({RAD * 1e3!r},0) [-5|5] "mrad/s" GYROSTAND'),
}


def _write(path: Path, frames) -> Path:
    with can.Logger(str(path)) as lg:
        for f in frames:
            lg.on_message_received(f)
    return path


def _replay(cfg: Path, log: Path, out: Path, *extra: str) -> tuple[int, dict]:
    buf, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        rc = cli_main(["replay", str(cfg), str(log), "--out", str(out), "--json", *extra])
    return rc, json.loads(buf.getvalue()) if buf.getvalue().strip() else {}


def _samples(doc: dict) -> bytes:
    return (Path(doc["run_dir"]) / "az" / "samples.csv").read_bytes()


def _containers(raw: bytes) -> list[tuple[int, int, int]]:
    """(file offset, size, decompressed length) of each top-level container."""
    out, pos = [], blf.FILE_HEADER_SIZE
    head, cont = blf.OBJ_HEADER_BASE_STRUCT, blf.LOG_CONTAINER_STRUCT
    while pos + head.size <= len(raw):
        _, _, _, size, _ = head.unpack_from(raw, pos)
        data = zlib.decompress(raw[pos + head.size + cont.size:pos + size])
        out.append((pos, size, len(data)))
        pos += size + size % 4
    return out


def _objects(raw: bytes, conts) -> list[tuple[int, int]]:
    """[start, end) of every object in the decompressed stream of all containers."""
    head, cont = blf.OBJ_HEADER_BASE_STRUCT, blf.LOG_CONTAINER_STRUCT
    stream = b"".join(zlib.decompress(raw[p + head.size + cont.size:p + s])
                      for p, s, _ in conts)
    spans, pos = [], 0
    while (pos := stream.find(b"LOBJ", pos, pos + 8)) >= 0:
        _, _, _, size, _ = head.unpack_from(stream, pos)
        spans.append((pos, pos + size))
        pos += size
    return spans


def damaged_containers(tmp: Path, cfg: Path, log: Path, n: int) -> list[str]:
    raw = log.read_bytes()
    conts = _containers(raw)
    spans = _objects(raw, conts)
    starts = [sum(c[2] for c in conts[:k]) for k in range(len(conts) + 1)]
    lines = [f"1. damaged containers: {len(conts)} containers, {n} frames"]
    events = [[k] for k in range(len(conts))] + [[1, 3], [0, len(conts) - 1]]
    for path_args, label in (([], "arrays"), (["--per-frame"], "per-frame")):
        worst = 0
        for ks in events:
            bad = bytearray(raw)
            hit: set[int] = set()
            for k in ks:
                pos, size, _ = conts[k]
                mid = pos + 32 + size // 2
                bad[mid:mid + 4] = bytes(b ^ 0xFF for b in bad[mid:mid + 4])
                hit |= {i for i, (a, b) in enumerate(spans)
                        if a < starts[k + 1] and b > starts[k]}
            p = tmp / "damaged.blf"
            p.write_bytes(bytes(bad))
            rc, doc = _replay(cfg, p, tmp / "dmg", *path_args)
            lost = n - doc["stats"]["decoder"]["received"]
            worst = max(worst, lost - len(hit))
            if label == "arrays":
                lines.append(f"   container(s) {ks}: exit {rc}, frames lost {lost} "
                             f"(objects in the damaged container(s): {len(hit)}), "
                             f"containers skipped {doc['stats']['log']['containers_skipped']}")
        lines.append(f"   {label}: frames lost beyond the damaged containers' own, worst "
                     f"over {len(events)} events: {worst}")
    return lines


def sna_codes(tmp: Path, cfg: Path, frames) -> list[str]:
    text = DBC.read_text(encoding="cp1252").replace(
        TEMP, ' SG_ Temperature : 0|16@1- (0.01,0) [-60|400] "degC" GYROSTAND')
    text += 'VAL_ 272 Temperature 32767 "NotAvailable" 32000 "Error" ;\n'
    dbc = tmp / "codes.dbc"
    dbc.write_text(text)
    db = cantools.database.load_file(str(dbc))
    d = yaml.safe_load(cfg.read_text())
    d["dbc"] = str(dbc)
    ccfg = tmp / "codes.yaml"
    ccfg.write_text(yaml.safe_dump(d))
    lines = ["2. SNA codes (VAL_ NotAvailable/Error inside the range) in temperature frames"]
    for every in (100, 10, 2):
        out, k, injected = [], 0, 0
        for f in frames:
            if f.arbitration_id == 0x110:
                k += 1
                if k % every == 0:
                    v = db.decode_message(0x110, f.data, decode_choices=False)
                    v["Temperature"] = 327.67 if k % 2 else 320.0
                    f = can.Message(timestamp=f.timestamp, arbitration_id=0x110,
                                    is_extended_id=False, data=db.encode_message(0x110, v))
                    injected += 1
            out.append(f)
        p = _write(tmp / f"codes{every}.blf", out)
        rc, doc = _replay(ccfg, p, tmp / "codes")
        dec = doc["stats"]["decoder"]
        temps = [float(r.split(",")[2]) for r in _samples(doc).decode().splitlines()[1:]
                 if r.split(",")[2]]
        lines.append(f"   1 in {every}: injected {injected}, rejected.not_available "
                     f"{dec['rejected']['not_available']}, max temperature bin "
                     f"{max(temps):.2f} degC, exit {rc}")
    return lines


def unit_variants(tmp: Path, cfg: Path, log: Path) -> list[str]:
    rc, base = _replay(cfg, log, tmp / "base")
    want = [r.split(",") for r in _samples(base).decode().splitlines()[1:]]
    lines = ["3. unit variants (the same raw bits, declared in another unit)"]
    for name, (old, new) in UNITS.items():
        text = DBC.read_text(encoding="cp1252").replace(old, new)
        dbc = tmp / "u.dbc"
        dbc.write_text(text, encoding="utf-8")
        d = yaml.safe_load(cfg.read_text())
        d["dbc"] = str(dbc)
        d["session"]["drift_unit"] = "deg/h"
        ucfg = tmp / "u.yaml"
        ucfg.write_text(yaml.safe_dump(d, allow_unicode=True), encoding="utf-8")
        rc, doc = _replay(ucfg, log, tmp / "u")
        got = [r.split(",") for r in _samples(doc).decode().splitlines()[1:]]
        diff = max(abs(float(a[i]) - float(b[i])) for a, b in zip(got, want, strict=True)
                   for i in (1, 2) if a[i] and b[i])
        lines.append(f"   {name:>7}: exit {rc}, bins {len(got)}, max |sample - degC/deg/h "
                     f"sample| {diff:.2e}")
    return lines


def storm(tmp: Path, cfg: Path, frames, log: Path) -> list[str]:
    rc, base = _replay(cfg, log, tmp / "calm")
    extra = []
    for i, f in enumerate(frames):
        for j in range(8):
            t = f.timestamp + 1e-5 * (j + 1)
            extra.append(can.Message(timestamp=t, arbitration_id=0x7A0 + (i + j) % 16,
                                     is_extended_id=False, data=bytes(8)))
        if i % 3 == 0:  # an id of the DBC no channel maps
            extra.append(can.Message(timestamp=f.timestamp + 2e-5, arbitration_id=0x101,
                                     is_extended_id=False, data=bytes(8)))
    stormy = sorted(list(frames) + extra, key=lambda m: m.timestamp)
    p = _write(tmp / "storm.blf", stormy)
    t0 = time.perf_counter()
    rc, doc = _replay(cfg, p, tmp / "storm")
    dt = time.perf_counter() - t0
    dec = doc["stats"]["decoder"]
    same = _samples(doc) == _samples(base)
    return ["4. signal storm", f"   {len(extra)} storm frames among {len(frames)}: exit {rc}, "
            f"received {dec['received']}, unknown_id {dec['rejected']['unknown_id']}, "
            f"ignored {dec['ignored']}, clean frames lost "
            f"{len(frames) - dec['decoded']}, samples.csv identical to the calm replay: "
            f"{same} ({dt:.1f} s, {dec['received'] / dt:,.0f} frames/s)"]


def main() -> list[str]:
    logging.basicConfig(level=logging.ERROR)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        cfg, frames = simulated_session(tmp, duration=1200.0)
        log = _write(tmp / "stand.blf", frames)
        lines = []
        lines += damaged_containers(tmp, cfg, log, len(frames))
        lines += sna_codes(tmp, cfg, frames)
        lines += unit_variants(tmp, cfg, log)
        lines += storm(tmp, cfg, frames, log)
    for ln in lines:
        print(ln, flush=True)
    return lines


if __name__ == "__main__":
    main()
