"""Summarises a ULog's sensor topics with pyulog, the independent reader tests/formats/ulog_test.cc
compares calibd's ULog reader with (SPEC §9; formats/ulog.h says what is read and how).

Usage: python3 ulog_pyulog_summary.py FILE.ulg   (pyulog's package on PYTHONPATH)
Prints one line per stream: "topic:multi_id kind count first_ns last_ns mean..." where the times
are in ns and the means are of the SI values (mag in µT), with full precision.
"""
import sys

import numpy as np
from pyulog import ULog

TRIADS = {"sensor_accel": "accelerometer", "sensor_gyro": "gyroscope", "sensor_mag": "magnetometer"}
FIFOS = {"sensor_accel_fifo": "accelerometer", "sensor_gyro_fifo": "gyroscope"}
RELATIVE_INVALID = 0x7FFFFFFF


def sample_times(d):
    """timestamp_sample when present and non-zero in every message, else timestamp (ns)."""
    t = d["timestamp"].astype(np.int64)
    if "timestamp_sample" in d and np.all(d["timestamp_sample"] != 0):
        t = d["timestamp_sample"].astype(np.int64)
    return t * 1000, d["timestamp"].astype(np.int64) * 1000


def emit(name, kind, t, values):
    means = " ".join(repr(float(m)) for m in np.mean(values, axis=0))
    print(name, kind, len(t), int(t[0]), int(t[-1]), means)


def main():
    log = ULog(sys.argv[1])
    for ds in log.data_list:
        d, name = ds.data, "%s:%d" % (ds.name, ds.multi_id)
        if ds.name in TRIADS or ds.name in FIFOS:
            t, _ = sample_times(d)
            if ds.name in TRIADS:
                scale = 100.0 if ds.name == "sensor_mag" else 1.0
                v = np.stack([d[a].astype(np.float64) * scale for a in "xyz"], axis=1)
                emit(name, TRIADS[ds.name], t, v)
            else:
                ts, vs = [], []
                for i in range(len(t)):
                    n, dt = int(d["samples"][i]), float(d["dt"][i])
                    for k in range(n):
                        ts.append(t[i] - int(round((n - 1 - k) * dt * 1000)))
                        vs.append([float(d["%s[%d]" % (a, k)][i]) * float(d["scale"][i])
                                   for a in "xyz"])
                if ts:
                    emit(name, FIFOS[ds.name], np.array(ts), np.array(vs))
            if "temperature" in d:
                temp = d["temperature"].astype(np.float64)
                ok = np.isfinite(temp)
                if np.any(ok):
                    emit(name, "temperature", t[ok], temp[ok].reshape(-1, 1))
        elif ds.name == "sensor_combined":
            t = d["timestamp"].astype(np.int64) * 1000
            emit(name, "gyroscope", t, np.stack([d["gyro_rad[%d]" % k] for k in range(3)], axis=1)
                 .astype(np.float64))
            rel = d.get("accelerometer_timestamp_relative", np.zeros(len(t), dtype=np.int64))
            ok = rel != RELATIVE_INVALID
            emit(name, "accelerometer", t[ok] + rel[ok].astype(np.int64) * 1000,
                 np.stack([d["accelerometer_m_s2[%d]" % k] for k in range(3)], axis=1)[ok]
                 .astype(np.float64))


if __name__ == "__main__":
    main()
