#!/usr/bin/env python3
"""The product tree against the structure rules of issue #23 (tracker 29), as a ratchet.

Rules: no product file over 800 lines, no function over 150 lines, no product file outside
methods/<name>/ and the registry (methods/registry.*) that names a method (a string literal "pca",
"array", ..., comments included), base/ free of method vocabulary, and every failure Reason defined
in product code (base/status.h's generic ones, a method's own `<name>_reason::` beside its
numerics) with a catalog entry (CatalogEntry / E(...) in server/failure_reasons.cc or a method's
FailureReasons()). Today's offenders are recorded in scripts/structure_baseline.json with their
sizes;
the check fails when a new offender appears or a recorded one grows, so the tree only moves
towards the rules. After a refactor shrinks an offender, `--update` records the smaller figures.

  scripts/check_structure.py            # check (exit 1 naming what broke a rule)
  scripts/check_structure.py --report   # every offender with its size
  scripts/check_structure.py --update   # record today's offenders as the baseline

Function lengths are found the Google-style way: a signature starting in column 0 of a .cc or .h
file, a body closed by a lone '}' in column 0 (functions inside class bodies are not counted).
"""
import argparse
import json
import os
import re
import sys
from collections import defaultdict

PRODUCT_DIRS = ["base", "core", "results", "formats", "methods", "storage", "server", "web"]
METHODS = ["pca", "array", "imu", "noise", "thermal", "mag"]
# Files that may name a method besides its folder: the registry, which lists them all.
REGISTRY = ("methods/registry.h", "methods/registry.cc")
# A name that is the same word but not the method: (file, name) -> why.
NOT_THE_METHOD = {
    ("formats/recording.cc", "array"): "the stored name of the inertial-log layout (SPEC §2)",
}
# JSON Schema's type keyword (server/openapi.cc): {"type", "array"} names a JSON type.
JSON_SCHEMA_TYPE = re.compile(r'\{"type", "array"\}')
MAX_FILE_LINES = 800
MAX_FUNCTION_LINES = 150
HERE = os.path.dirname(os.path.abspath(__file__))
BASELINE = os.path.join(HERE, "structure_baseline.json")


def product_files(root):
    for d in PRODUCT_DIRS:
        for dirpath, _, names in os.walk(os.path.join(root, d)):
            for n in sorted(names):
                if n.endswith((".cc", ".h")):
                    yield os.path.relpath(os.path.join(dirpath, n), root)


def functions(lines):
    """Yields (name, first line, length) of every namespace-level function body."""
    start = None
    raw_end = None  # the closing delimiter of a raw string literal being skipped
    for i, line in enumerate(lines):
        if raw_end is not None:
            if raw_end in line:
                raw_end = None
            continue
        m = re.search(r'R"([^(\s]*)\(', line)
        if m and (')%s"' % m.group(1)) not in line[m.end():]:
            raw_end = ')%s"' % m.group(1)
        if start is None:
            if line and not line[0].isspace() and not line.startswith(
                    ("}", "#", "//", "namespace", "using", "extern", "template <")) and \
                    not line.rstrip().endswith((";", "}")) and " = " not in line:
                start = i
            continue
        if line.rstrip() == "}":
            signature = " ".join(l.strip() for l in lines[start:i])
            name = re.search(r"([A-Za-z_][\w:~]*)\s*\(", signature)
            yield (name.group(1) if name else lines[start].strip()), start + 1, i - start + 1
            start = None
        elif line.startswith(("};", "}  //")):
            start = None


# A reason's definition: `inline constexpr Reason Reason::kName{"code"}` (generic) or, inside
# `namespace <name>_reason {`, `inline constexpr Reason kName{"code"}`.
REASON_DEFINITION = re.compile(r'constexpr Reason (Reason::)?(k\w+)\{"')
REASON_NAMESPACE = re.compile(r'namespace (\w+_reason) \{')
# A catalog entry: `E(R::kName,` (server/failure_reasons.cc, R = Reason) or
# `CatalogEntry(core::<name>_reason::kName,` / `CatalogEntry(Reason::kName,`.
REASON_ENTRY = re.compile(r'(?:\bE\(R::|CatalogEntry\(\s*(?:\w+::)*?(?:(\w+_reason)::|Reason::))(k\w+)')


def reasons(text):
    """(defined, catalogued): qualified names (Reason::kX, <name>_reason::kX) in this file."""
    defined, catalogued = set(), set()
    for m in REASON_DEFINITION.finditer(text):
        if m.group(1):
            defined.add("Reason::" + m.group(2))
        else:
            ns = REASON_NAMESPACE.findall(text[:m.start()])
            defined.add("%s::%s" % (ns[-1] if ns else "?", m.group(2)))
    for m in REASON_ENTRY.finditer(text):
        catalogued.add("%s::%s" % (m.group(1) or "Reason", m.group(2)))
    return defined, catalogued


def measure(root):
    files, funcs, mentions = {}, {}, defaultdict(list)
    defined, catalogued = {}, set()
    for f in product_files(root):
        with open(os.path.join(root, f), encoding="utf-8") as fh:
            text = fh.read()
        d, c = reasons(text)
        defined.update({r: f for r in d})
        catalogued |= c
        lines = text.split("\n")
        if len(lines) > MAX_FILE_LINES:
            files[f] = len(lines)
        for name, _, n in functions(lines):
            if n > MAX_FUNCTION_LINES:
                key = "%s:%s" % (f, name)
                funcs[key] = max(n, funcs.get(key, 0))
        parts = f.split("/")
        if f in REGISTRY or (parts[0] == "methods" and len(parts) > 2 and parts[1] in METHODS):
            continue  # a method's own folder, or the registry
        text = JSON_SCHEMA_TYPE.sub("", text)
        for m in METHODS:
            if '"%s"' % m in text and (f, m) not in NOT_THE_METHOD:
                mentions[m].append(f)
    defined.pop("Reason::kUnspecified", None)
    uncatalogued = {r: f for r, f in defined.items() if r not in catalogued}
    return files, funcs, {m: sorted(mentions[m]) for m in METHODS}, uncatalogued


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default=os.path.dirname(HERE))
    ap.add_argument("--baseline", default=BASELINE)
    ap.add_argument("--report", action="store_true")
    ap.add_argument("--update", action="store_true")
    args = ap.parse_args()
    files, funcs, mentions, uncatalogued = measure(args.root)
    counts = {m: len(v) for m, v in mentions.items()}
    if args.update:
        with open(args.baseline, "w") as fh:
            json.dump({"files": files, "functions": funcs, "method_mentions": counts}, fh,
                      indent=1, sort_keys=True)
            fh.write("\n")
        print("recorded %d files, %d functions" % (len(files), len(funcs)))
        return 0
    if args.report:
        for f, n in sorted(files.items(), key=lambda x: -x[1]):
            print("file %5d  %s" % (n, f))
        for f, n in sorted(funcs.items(), key=lambda x: -x[1]):
            print("function %5d  %s" % (n, f))
        for m, fs in mentions.items():
            print('"%s" named outside methods/ in %d files: %s' % (m, len(fs), " ".join(fs)))
        for r, f in sorted(uncatalogued.items()):
            print("reason without a catalog entry: %s (%s)" % (r, f))
    with open(args.baseline) as fh:
        base = json.load(fh)
    problems = []
    for f, n in sorted(files.items()):
        allowed = base["files"].get(f)
        if allowed is None or n > allowed:
            problems.append("%s has %d lines, over the limit of %d%s: split it" % (
                f, n, MAX_FILE_LINES, "" if allowed is None else " and its recorded %d" % allowed))
    for f, n in sorted(funcs.items()):
        allowed = base["functions"].get(f)
        if allowed is None or n > allowed:
            problems.append("function %s has %d lines, over the limit of %d%s: split it" % (
                f, n, MAX_FUNCTION_LINES, "" if allowed is None else
                " and its recorded %d" % allowed))
    for m, n in sorted(counts.items()):
        allowed = base["method_mentions"].get(m, 0)
        if n > allowed:
            problems.append('"%s" is named outside methods/ in %d files, recorded %d: %s' % (
                m, n, allowed, " ".join(mentions[m])))
    base_files = sorted({f for fs in mentions.values() for f in fs if f.startswith("base/")})
    if base_files:
        problems.append("base/ names a method: %s" % " ".join(base_files))
    for r, f in sorted(uncatalogued.items()):
        problems.append("failure reason %s (%s) has no catalog entry: add one to "
                        "server/failure_reasons.cc or its method's FailureReasons()" % (r, f))
    for p in problems:
        print("structure: " + p)
    if problems:
        print("structure: %d rule(s) broken (scripts/check_structure.py; shrinking an offender? "
              "--update records it)" % len(problems))
        return 1
    print("structure: no rule broken beyond the recorded offenders (%d files, %d functions)" %
          (len(files), len(funcs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
