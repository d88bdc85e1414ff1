#!/usr/bin/env python3
"""Runs `pbrlod ARGS...` as the tool's tests do (CROSSCOMPILING_EMULATOR of the pbrlod target,
examples/CMakeLists.txt) and, when ARGS ask for --json and the command succeeds, holds its
standard output to strict JSON: exactly one object, no key twice in any object, no NaN or
Infinity, nothing after it. Output and exit code pass through otherwise, so each test's own
PASS_REGULAR_EXPRESSION still applies; a violation prints why and exits 3."""
import json
import subprocess
import sys


def no_repeats(pairs):
    seen = set()
    for k, _ in pairs:
        if k in seen:
            raise ValueError(f"the key {k!r} appears twice in one object")
        seen.add(k)
    return dict(pairs)


def refuse_constant(name):
    raise ValueError(f"{name} is not JSON")


def main():
    cmd = sys.argv[1:]
    run = subprocess.run(cmd, stdout=subprocess.PIPE)
    sys.stdout.buffer.write(run.stdout)
    sys.stdout.flush()
    if run.returncode != 0 or "--json" not in cmd:
        return run.returncode
    try:
        value = json.loads(run.stdout.decode("utf-8"), object_pairs_hook=no_repeats,
                           parse_constant=refuse_constant)
        if not isinstance(value, dict):
            raise ValueError("the output is not one JSON object")
    except ValueError as e:  # json.JSONDecodeError is a ValueError
        print(f"strict_json: {' '.join(cmd[1:])}: invalid JSON: {e}", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
