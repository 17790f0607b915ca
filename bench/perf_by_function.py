"""Where the compiled loop's samples fall: a ``perf`` profile of ``bench/profile_modal_drill.py`` by function.

``perf`` cannot name the functions numba compiles at run time; ``profile_modal_drill.py --addresses`` writes their
start addresses (a fresh numba cache compiles them in the process). Each sample of ``perf script -F
time,ip,sym,dso`` is named by perf where it can (OpenBLAS, libc, the interpreter), else by the compiled function
whose start lies closest below it (NRT_incref / NRT_decref are numba's atomic reference counts). Only the last
``--window`` seconds of samples count, ending at the last sample in the loop ``run``: the advance, not the
compilation before it.

    NUMBA_CACHE_DIR=$(mktemp -d) perf record -F 4000 -o perf.data .venv/bin/python bench/profile_modal_drill.py \\
        --ms 40 --addresses addresses.json
    perf script -i perf.data -F time,ip,sym,dso > samples.txt
    .venv/bin/python bench/perf_by_function.py samples.txt addresses.json --window 0.35
"""

from __future__ import annotations

import argparse
import bisect
import collections
import json
import re

SAMPLE = re.compile(r"\s*([\d.]+):\s+([0-9a-f]+) (.*) \((.*)\)$")


def short_name(mangled: str) -> str:
    """The last two parts of a numba function's mangled name (module.function)."""
    text = mangled[3:] if mangled.startswith("_ZN") else mangled
    names, i = [], 0
    while i < len(text) and text[i].isdigit():
        j = i
        while text[j].isdigit():
            j += 1
        length = int(text[i:j])
        names.append(text[j:j + length])
        i = j + length
    return ".".join(names[-2:]) if names else mangled[:40]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("samples", help="perf script -F time,ip,sym,dso output")
    parser.add_argument("addresses", help="profile_modal_drill.py --addresses output")
    parser.add_argument("--window", type=float, default=0.35, help="the last seconds of samples [s]")
    parser.add_argument("--top", type=int, default=20)
    args = parser.parse_args()
    with open(args.addresses) as fh:
        starts = sorted((address, name) for name, address in json.load(fh).items())
    keys = [address for address, _ in starts]

    def name(ip: int, symbol: str, dso: str) -> str:
        if symbol != "[unknown]":
            return f"{symbol} ({dso})"
        k = bisect.bisect_right(keys, ip) - 1
        if k >= 0 and ip - keys[k] < 300_000:
            return short_name(starts[k][1])
        return f"? ({dso})"

    samples = []
    with open(args.samples) as fh:
        for line in fh:
            match = SAMPLE.match(line)
            if match:
                time_s, ip, symbol, dso = match.groups()
                samples.append((float(time_s), name(int(ip, 16), symbol, dso.split("/")[-1])))
    end = max(t for t, n in samples if n.startswith("kernel.run"))
    counts = collections.Counter(n for t, n in samples if end - args.window <= t <= end)
    total = sum(counts.values())
    print(f"{total} samples in the last {args.window:g} s")
    for label, count in counts.most_common(args.top):
        print(f"{100 * count / total:6.1f} % {label}")


if __name__ == "__main__":
    main()
