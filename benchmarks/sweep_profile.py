"""Where a sweep's time goes, instruction by instruction: perf samples mapped onto its machine code.

numba's compiled code has no symbols that ``perf report`` could show, so this script finds the
sweep kernel's code itself: it builds a case of benchmarks/hydro_throughput.py, takes two
warm-up steps (kernels from numba's cache), looks up the address of the compiled
:func:`impactpipe.hydro.scheme.directional.sweep` and the executable anonymous mapping that holds
it (``/proc/self/maps``), writes that mapping's bytes to a file, samples its own process with
``perf record -e cpu-clock`` (a software clock: no hardware counters needed) over ``--steps``
steps, and counts the samples by instruction address.  It prints the share of the samples in
the sweep's mapping, the hottest 256-byte windows of it, and the hottest instructions with their
disassembly (``objdump``).  A sample names the instruction after the one that stalled (skid):
read the lines just above a hot one.  Needs ``perf`` (with access to the process's samples)
and ``objdump`` on the PATH.

    NUMBA_NUM_THREADS=1 python benchmarks/sweep_profile.py [--case 2d-ideal-gas] [--steps 100] [--top 25]
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numba

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.scheme.directional import sweep  # noqa: E402

#: Bytes of code per window of the summary by address.
WINDOW = 256


def sweep_address() -> int:
    """Entry address of the (first) compiled sweep."""
    compiled = next(iter(sweep.overloads.values()))
    return compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name)


def code_mapping(address: int) -> tuple[int, int]:
    """The (start, end) of the readable, executable mapping of this process that holds ``address``."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            span, perms = line.split()[:2]
            lo, hi = (int(x, 16) for x in span.split("-"))
            if lo <= address < hi and perms.startswith("r") and "x" in perms:
                return lo, hi
    raise RuntimeError(f"no readable executable mapping holds {address:#x}")


def sampled_addresses(perf_data: str) -> list[int]:
    """Instruction addresses of every sample in ``perf_data``."""
    out = subprocess.run(["perf", "script", "-i", perf_data, "-F", "ip"], capture_output=True, text=True, check=True)
    return [int(line, 16) for line in out.stdout.split() if line]


def disassembly(code_file: str, start: int) -> dict[int, str]:
    """Address -> instruction text of the code in ``code_file``, loaded at ``start``."""
    out = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"--adjust-vma={start:#x}", code_file],
                         capture_output=True, text=True, check=True)
    lines = {}
    for line in out.stdout.splitlines():
        match = re.match(r"\s*([0-9a-f]+):\s+(?:[0-9a-f]{2} )+\s*(.*)", line)
        if match:
            lines[int(match.group(1), 16)] = match.group(2).strip()
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="2d-ideal-gas", help="a case of benchmarks/hydro_throughput.py")
    parser.add_argument("--quick", action="store_true", help="the case's smaller mesh")
    parser.add_argument("--steps", type=int, default=100, help="sampled steps (default 100)")
    parser.add_argument("--top", type=int, default=25, help="hottest instructions and windows printed")
    args = parser.parse_args()
    for tool in ("perf", "objdump"):
        if shutil.which(tool) is None:
            sys.exit(f"sweep_profile: needs {tool} on the PATH")
    sim = build(args.case, args.quick)
    sim.step()
    sim.step()
    lo, hi = code_mapping(sweep_address())
    with tempfile.TemporaryDirectory() as work:
        code_file = os.path.join(work, "sweep.bin")
        with open(code_file, "wb") as out:
            out.write(ctypes.string_at(lo, hi - lo))
        perf_data = os.path.join(work, "perf.data")
        perf = subprocess.Popen(["perf", "record", "-q", "-e", "cpu-clock", "-F", "2000", "-p", str(os.getpid()),
                                 "-o", perf_data], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)
        start_updates = sim.cell_updates
        t0 = time.perf_counter()
        for _ in range(args.steps):
            sim.step()
        wall = time.perf_counter() - t0
        perf.send_signal(signal.SIGINT)
        perf.wait()
        samples = sampled_addresses(perf_data)
        code = disassembly(code_file, lo)
    ns = wall / (sim.cell_updates - start_updates) * 1e9
    in_sweep = collections.Counter(a for a in samples if lo <= a < hi)
    total = len(samples)
    print(f"{args.case}: {ns:.1f} ns per cell-update over {args.steps} steps on {numba.get_num_threads()} thread(s); "
          f"{total} samples, {100 * sum(in_sweep.values()) / max(total, 1):.1f} % in the sweep's code "
          f"(the rest: the other kernels, numpy and Python)")
    windows = collections.Counter()
    for address, count in in_sweep.items():
        windows[(address - lo) // WINDOW] += count
    print(f"hottest {WINDOW}-byte windows (offset in the mapping, % of all samples):")
    for window, count in windows.most_common(args.top):
        print(f"  +{window * WINDOW:#08x}  {100 * count / total:5.1f}")
    print("hottest instructions (offset, % of all samples, instruction):")
    for address, count in in_sweep.most_common(args.top):
        print(f"  +{address - lo:#08x}  {100 * count / total:5.1f}  {code.get(address, '?')}")


if __name__ == "__main__":
    main()
