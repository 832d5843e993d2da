"""YAML session configuration: loaded with ``yaml.safe_load``, validated at load, frozen.

Every problem is a :class:`~gyrostand.errors.ConfigError` whose message starts with the file
and the key path, e.g.::

    configs/demo.yaml: gyros[1].drift.signal: 'Drft' is not a signal of message
    GYRO_DRIFT_1 in dbc/gyrostand.dbc (known: Drift, Counter)

Unknown keys are errors. Relative paths (``dbc``, ``session.output``) resolve against the
folder of the config file. Messages are named by DBC name or frame id (int, e.g. ``0x100``;
add ``extended: true/false`` when a DBC has both kinds with that id); signals are resolved
in the DBC at load, including signals under a multiplexer. Shape (``simulate`` and
``responses`` optional; see ``configs/demo.yaml`` for every key)::

    session: {name: run-42, output: runs}
    bus: {interface: virtual, channel: stand0}     # passed to can.Bus as is
    dbc: dbc/gyrostand.dbc
    sampling: {dt: 1.0}
    gyros:
      - name: az
        drift: {message: GYRO_DRIFT_1, signal: Drift, counter: Counter}
        temperature: {message: GYRO_TEMP_1, signal: Temperature}
        model: [markov, temp, bias]
        identifiers: [lkf, lsq]
        result: {message: GS_RESULT_1, summary: GS_SUMMARY_1}
"""


from __future__ import annotations

from .parser import decode_text, load_config, parse_config, parse_text
from .schema import (
    ACK_SIGNALS,
    COMMAND_SIGNALS,
    IDENTIFIERS,
    MATCHES,
    MAX_DT,
    MAX_EPOCH,
    MAX_GAP_BINS,
    MAX_RATE_HZ,
    MIN_DT,
    MIN_RATE_HZ,
    MODEL_TERMS,
    RESULT_SIGNALS,
    STATUS_SIGNALS,
    SUMMARY_SIGNALS,
    ChannelConfig,
    GyroConfig,
    LkfConfig,
    ReconnectConfig,
    ResponsesConfig,
    ResultConfig,
    SamplingConfig,
    SessionConfig,
    SimGyroConfig,
    SimulateConfig,
)

__all__ = [
    "MODEL_TERMS",
    "IDENTIFIERS",
    "RESULT_SIGNALS",
    "SUMMARY_SIGNALS",
    "STATUS_SIGNALS",
    "COMMAND_SIGNALS",
    "ACK_SIGNALS",
    "MIN_RATE_HZ",
    "MAX_RATE_HZ",
    "MIN_DT",
    "MAX_DT",
    "MAX_GAP_BINS",
    "MAX_EPOCH",
    "MATCHES",
    "ChannelConfig",
    "ResultConfig",
    "LkfConfig",
    "GyroConfig",
    "SamplingConfig",
    "ResponsesConfig",
    "ReconnectConfig",
    "SimGyroConfig",
    "SimulateConfig",
    "SessionConfig",
    "decode_text",
    "load_config",
    "parse_config",
    "parse_text",
]
