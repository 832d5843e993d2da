"""Write ``gyrostand.dbc`` (the project's frame catalogue) next to this script.

Run ``python dbc/generate.py [N_GYROS]`` from the repository root; the committed DBC is
this script's output for the default of 3 gyros. Pure string templates: no dependencies,
so the golden file and the script that made it stay side by side. The catalogue is
described in ``dbc/README.md``.
"""

from __future__ import annotations

import sys
from pathlib import Path

N_GYROS = 3
DRIFT_BASE = 0x100  # GYRO_DRIFT_n     = 0x100 + n - 1
TEMP_BASE = 0x110  # GYRO_TEMP_n      = 0x110 + n - 1
RESULT_BASE = 0x300  # GS_RESULT_n   = 0x300 + n - 1
SUMMARY_BASE = 0x310  # GS_SUMMARY_n = 0x310 + n - 1
STATUS_ID = 0x500
COMMAND_ID = 0x0F0  # above the data frames in priority: a stop is never starved
ACK_ID = 0x0F1

HEADER = """VERSION "gyrostand 1"


NS_ :
\tCM_
\tBA_DEF_
\tBA_
\tVAL_
\tBA_DEF_DEF_
\tSIG_VALTYPE_

BS_:

BU_: STAND GYROSTAND

"""

F32 = "[-3.4E+038|3.4E+038]"


def _gyro_messages(n: int) -> tuple[list[str], list[str], list[str], list[str]]:
    bo: list[str] = []
    cm: list[str] = []
    val: list[str] = []
    vt: list[str] = []
    d, t, r, s = (DRIFT_BASE + n - 1, TEMP_BASE + n - 1, RESULT_BASE + n - 1,
                  SUMMARY_BASE + n - 1)
    bo.append(
        f"BO_ {d} GYRO_DRIFT_{n}: 8 STAND\n"
        ' SG_ Drift : 0|32@1- (1E-005,0) [-1000|1000] "deg/h" GYROSTAND\n'
        ' SG_ Counter : 32|8@1+ (1,0) [0|255] "" GYROSTAND\n'
    )
    cm.append(f'CM_ BO_ {d} "Drift rate of gyro {n}, sent by the stand at 10-1000 Hz.";')
    cm.append(f'CM_ SG_ {d} Drift "Gyro drift rate; 1e-5 deg/h per bit.";')
    cm.append(f'CM_ SG_ {d} Counter "Rolling counter, +1 per frame, wraps 255 -> 0.";')
    bo.append(
        f"BO_ {t} GYRO_TEMP_{n}: 8 STAND\n"
        ' SG_ Temperature : 0|16@1- (0.01,0) [-60|150] "degC" GYROSTAND\n'
        ' SG_ Counter : 16|8@1+ (1,0) [0|255] "" GYROSTAND\n'
    )
    cm.append(f'CM_ BO_ {t} "Built-in temperature sensor of gyro {n}.";')
    cm.append(f'CM_ SG_ {t} Temperature "Gyro temperature; 0.01 degC per bit.";')
    cm.append(f'CM_ SG_ {t} Counter "Rolling counter, +1 per frame, wraps 255 -> 0.";')
    bo.append(
        f"BO_ {r} GS_RESULT_{n}: 8 GYROSTAND\n"
        ' SG_ Kind M : 0|4@1+ (1,0) [0|1] "" STAND\n'
        ' SG_ Identifier : 4|4@1+ (1,0) [0|2] "" STAND\n'
        ' SG_ Param : 8|8@1+ (1,0) [0|254] "" STAND\n'
        f' SG_ Value m0 : 16|32@1- (1,0) {F32} "" STAND\n'
        f' SG_ Std m1 : 16|32@1- (1,0) [0|3.4E+038] "" STAND\n'
        ' SG_ NParams : 48|8@1+ (1,0) [0|255] "" STAND\n'
        ' SG_ Counter : 56|8@1+ (1,0) [0|255] "" STAND\n'
    )
    cm.append(f'CM_ BO_ {r} "Identified parameter of gyro {n}: Kind 0 carries the estimate, '
              'Kind 1 its standard deviation (IEEE float32, the parameter\'s own unit).";')
    cm.append(f'CM_ SG_ {r} Param "Index into the model\'s parameter list (0-based).";')
    cm.append(f'CM_ SG_ {r} NParams "Number of parameters in the model.";')
    cm.append(f'CM_ SG_ {r} Counter "Result round, +1 per published set, wraps.";')
    val.append(f'VAL_ {r} Kind 0 "value" 1 "std" ;')
    val.append(f'VAL_ {r} Identifier 0 "lkf" 1 "lsq" 2 "ml" ;')
    vt.append(f"SIG_VALTYPE_ {r} Value : 1;")
    vt.append(f"SIG_VALTYPE_ {r} Std : 1;")
    bo.append(
        f"BO_ {s} GS_SUMMARY_{n}: 8 GYROSTAND\n"
        ' SG_ Identifier : 0|4@1+ (1,0) [0|2] "" STAND\n'
        ' SG_ Status : 4|4@1+ (1,0) [0|4] "" STAND\n'
        ' SG_ ModelTerms : 8|16@1+ (1,0) [0|65535] "" STAND\n'
        ' SG_ Samples : 24|20@1+ (1,0) [0|1048575] "" STAND\n'
        ' SG_ ResidualRms : 44|20@1+ (1E-005,0) [0|10.48575] "deg/h" STAND\n'
    )
    cm.append(f'CM_ BO_ {s} "Fit summary of gyro {n}, one per identifier and result round.";')
    cm.append(f'CM_ SG_ {s} ModelTerms "Bit i set = vocabulary term i (markov=0, temp=1, '
              'white=2, bias=3, temp2=4, temp_lag=5, temp_rate=6, hysteresis=7, trend=8, '
              'warmup=9, random_walk=10, markov2=11).";')
    cm.append(f'CM_ SG_ {s} Samples "Number of bins used by the fit (saturates).";')
    cm.append(f'CM_ SG_ {s} ResidualRms "RMS of the one-step residuals (saturates).";')
    val.append(f'VAL_ {s} Identifier 0 "lkf" 1 "lsq" 2 "ml" ;')
    val.append(f'VAL_ {s} Status 0 "ok" 1 "warning" 2 "not_converged" 3 "failed" '
               '4 "insufficient_data" ;')
    return bo, cm, val, vt


def render(n_gyros: int = N_GYROS) -> str:
    bo: list[str] = []
    cm: list[str] = []
    val: list[str] = []
    vt: list[str] = []
    for n in range(1, n_gyros + 1):
        b, c, v, t = _gyro_messages(n)
        bo += b
        cm += c
        val += v
        vt += t
    bo.append(
        f"BO_ {STATUS_ID} GS_STATUS: 8 GYROSTAND\n"
        ' SG_ Page M : 0|4@1+ (1,0) [0|2] "" STAND\n'
        ' SG_ Counter : 4|4@1+ (1,0) [0|15] "" STAND\n'
        ' SG_ State m0 : 8|8@1+ (1,0) [0|4] "" STAND\n'
        ' SG_ Bins m0 : 16|24@1+ (1,0) [0|16777215] "" STAND\n'
        ' SG_ Gaps m0 : 40|24@1+ (1,0) [0|16777215] "" STAND\n'
        ' SG_ FramesDecoded m1 : 8|32@1+ (1,0) [0|4294967295] "" STAND\n'
        ' SG_ FramesRejected m1 : 40|24@1+ (1,0) [0|16777215] "" STAND\n'
        ' SG_ BusErrors m2 : 8|24@1+ (1,0) [0|16777215] "" STAND\n'
        ' SG_ LateFrames m2 : 32|24@1+ (1,0) [0|16777215] "" STAND\n'
        ' SG_ Outages m2 : 56|8@1+ (1,0) [0|255] "" STAND\n'
    )
    cm.append(f'CM_ BO_ {STATUS_ID} "Heartbeat, 1 Hz: pages 0, 1, 2 sent back to back with '
              'the same Counter. Counts are cumulative since start and wrap.";')
    cm.append(f'CM_ SG_ {STATUS_ID} Outages "Bus outages survived (reconnected); wraps.";')
    val.append(f'VAL_ {STATUS_ID} State 0 "idle" 1 "running" 2 "stopping" 3 "stopped" '
               '4 "fault" ;')
    bo.append(
        f"BO_ {COMMAND_ID} GS_COMMAND: 8 STAND\n"
        ' SG_ Command : 0|8@1+ (1,0) [1|4] "" GYROSTAND\n'
        ' SG_ Sequence : 8|8@1+ (1,0) [0|255] "" GYROSTAND\n'
        ' SG_ Target : 16|8@1+ (1,0) [0|255] "" GYROSTAND\n'
    )
    cm.append(f'CM_ BO_ {COMMAND_ID} "Command to a gyrostand daemon; answered by GS_ACK.";')
    cm.append(f'CM_ SG_ {COMMAND_ID} Target "Node id of the daemon addressed; 255 = all.";')
    val.append(f'VAL_ {COMMAND_ID} Command 1 "start" 2 "stop" 3 "reset" 4 "snapshot" ;')
    bo.append(
        f"BO_ {ACK_ID} GS_ACK: 8 GYROSTAND\n"
        ' SG_ Command : 0|8@1+ (1,0) [0|255] "" STAND\n'
        ' SG_ Sequence : 8|8@1+ (1,0) [0|255] "" STAND\n'
        ' SG_ Result : 16|8@1+ (1,0) [0|1] "" STAND\n'
        ' SG_ Reason : 24|8@1+ (1,0) [0|6] "" STAND\n'
        ' SG_ Node : 32|8@1+ (1,0) [0|255] "" STAND\n'
    )
    cm.append(f'CM_ BO_ {ACK_ID} "Acknowledgement of GS_COMMAND (echoes Command, Sequence).";')
    val.append(f'VAL_ {ACK_ID} Result 0 "ack" 1 "nack" ;')
    val.append(f'VAL_ {ACK_ID} Reason 0 "ok" 1 "unknown_command" 2 "wrong_state" 3 "busy" '
               '4 "malformed" 5 "not_for_me" 6 "rate_limited" ;')
    return (HEADER + "\n".join(bo) + "\n\n" + "\n".join(cm) + "\n\n" + "\n".join(val)
            + "\n\n" + "\n".join(vt) + "\n")


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else N_GYROS
    (Path(__file__).with_name("gyrostand.dbc")).write_text(render(n))
