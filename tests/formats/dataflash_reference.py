#!/usr/bin/env python3
"""Independent reading of a DataFlash log for tests/formats/dataflash_test.cc: pymavlink's DFReader
decodes the messages; this prints, per stream calibd reads (formats/dataflash.h), the sample count,
first and last time (ns) and the channel means in SI, as JSON.

Usage: PYTHONPATH=<dir holding the pymavlink package> dataflash_reference.py LOG.bin

DFReader imports pymavlink.mavutil, which builds MAVLink dialects from XML definitions at import
time (not in a source snapshot of pymavlink alone). DFReader uses it only to name flight modes and
vehicle types and to evaluate recv_match conditions, none of which this reading needs, so a stub
stands in for it; the log decoding is DFReader's own.
"""
import json
import sys
import types

import pymavlink

stub = types.ModuleType("pymavlink.mavutil")


class _AnyConstant:
    def __getattr__(self, name):
        return 0


stub.mavlink = _AnyConstant()
stub.mode_mapping_bynumber = lambda mav_type: {}
stub.mode_string_acm = str
stub.mode_string_px4 = str
stub.evaluate_condition = lambda condition, messages: True
sys.modules["pymavlink.mavutil"] = stub
pymavlink.mavutil = stub
from pymavlink import DFReader  # noqa: E402

# (message base name, kind, fields, factor to SI)
SPECS = [
    ("IMU", "accelerometer", ("AccX", "AccY", "AccZ"), 1.0),
    ("IMU", "gyroscope", ("GyrX", "GyrY", "GyrZ"), 1.0),
    ("IMU", "temperature", ("T",), 1.0),
    ("ACC", "accelerometer", ("AccX", "AccY", "AccZ"), 1.0),
    ("GYR", "gyroscope", ("GyrX", "GyrY", "GyrZ"), 1.0),
    ("MAG", "magnetometer", ("MagX", "MagY", "MagZ"), 0.1),  # milligauss -> uT
]


def add(streams, key, times, values):
    """times: (sample time, logging time, whether the sample time is there), in ns."""
    s = streams.setdefault(key, {"samples": 0, "first": times, "all_sampled": True,
                                 "sums": [0.0] * len(values)})
    s["samples"] += 1
    s["last"] = times
    s["all_sampled"] = s["all_sampled"] and times[2]
    for k, v in enumerate(values):
        s["sums"][k] += v


def finish(s):
    """calibd's rule (formats/dataflash.h): SampleUS where every sample of the stream has one."""
    which = 0 if s.pop("all_sampled") else 1
    s["first_ns"] = s.pop("first")[which]
    s["last_ns"] = s.pop("last")[which]
    s["means"] = [v / s["samples"] for v in s.pop("sums")]


def logged_ns(m):
    """The logging time: TimeUS, or TimeMS in the oldest logs."""
    return m.TimeUS * 1000 if hasattr(m, "TimeUS") else m.TimeMS * 1000000


def add_batch(streams, batches, m):
    """The samples of one ISBD of the batch sampler, timed and scaled by its ISBH."""
    h = batches.get(m.N)
    if h is None:
        return
    kind = {0: "accelerometer", 1: "gyroscope"}[h.type]
    for j in range(32):
        k = 32 * m.seqno + j
        if k >= h.smp_cnt:
            break
        t_ns = h.SampleUS * 1000 + round(k * 1e9 / h.smp_rate)
        add(streams, "ISBD:%d %s" % (h.instance, kind), (t_ns, t_ns, True),
            [m.x[j] / h.mul, m.y[j] / h.mul, m.z[j] / h.mul])


def main(path):
    log = DFReader.DFReader_binary(path, zero_time_base=True)
    streams = {}
    batches = {}
    while True:
        m = log.recv_msg()
        if m is None:
            break
        name = m.get_type()
        if name == "ISBH":
            batches[m.N] = m
        elif name == "ISBD":
            add_batch(streams, batches, m)
        for base, kind, fields, factor in SPECS:
            if name == base:
                instance = getattr(m, "I", 0)
            elif len(name) == len(base) + 1 and name.startswith(base) and name[-1] in "23456789":
                instance = int(name[-1]) - 1
            else:
                continue
            if not all(hasattr(m, f) for f in fields):
                continue
            # Both times; a stream uses SampleUS only where every sample has one (finish()).
            sample_us = getattr(m, "SampleUS", 0)
            add(streams, "%s:%d %s" % (base, instance, kind),
                (sample_us * 1000, logged_ns(m), sample_us != 0),
                [getattr(m, f) * factor for f in fields])
    for s in streams.values():
        finish(s)
    json.dump(streams, sys.stdout, indent=1, sort_keys=True)


if __name__ == "__main__":
    main(sys.argv[1])
