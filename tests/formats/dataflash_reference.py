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
    ("IMU", "accel", ("AccX", "AccY", "AccZ"), 1.0),
    ("IMU", "gyro", ("GyrX", "GyrY", "GyrZ"), 1.0),
    ("IMU", "temperature", ("T",), 1.0),
    ("ACC", "accel", ("AccX", "AccY", "AccZ"), 1.0),
    ("GYR", "gyro", ("GyrX", "GyrY", "GyrZ"), 1.0),
    ("MAG", "mag", ("MagX", "MagY", "MagZ"), 0.1),  # milligauss -> uT
]


def main(path):
    log = DFReader.DFReader_binary(path, zero_time_base=True)
    streams = {}
    while True:
        m = log.recv_msg()
        if m is None:
            break
        name = m.get_type()
        for base, kind, fields, factor in SPECS:
            if name == base:
                instance = getattr(m, "I", 0)
            elif len(name) == len(base) + 1 and name.startswith(base) and name[-1] in "23456789":
                instance = int(name[-1]) - 1
            else:
                continue
            if not all(hasattr(m, f) for f in fields):
                continue
            us = getattr(m, "SampleUS", 0) or m.TimeUS
            s = streams.setdefault("%s:%d %s" % (base, instance, kind),
                                   {"samples": 0, "first_ns": us * 1000, "sums": [0.0] * len(fields)})
            s["samples"] += 1
            s["last_ns"] = us * 1000
            for k, f in enumerate(fields):
                s["sums"][k] += getattr(m, f) * factor
    for s in streams.values():
        s["means"] = [v / s["samples"] for v in s.pop("sums")]
    json.dump(streams, sys.stdout, indent=1, sort_keys=True)


if __name__ == "__main__":
    main(sys.argv[1])
