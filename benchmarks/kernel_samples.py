"""Where a CPU kernel spends its time, instruction by instruction: ``perf record -e cpu-clock`` samples of a replayed
render (``job_render_replay.py``'s captured calls) mapped onto the kernel's compiled code in Warp's cache.

``python3 benchmarks/kernel_samples.py calls.pkl [--kernel resolve_samples] [--images 64] [--top 12] [--asm]``

valgrind no longer decodes the kernels (AVX-512 in Warp's CPU code: ``job_render_replay.py``'s docstring); timer
sampling needs no decoding and no hardware counters. The replay runs in a child process under ``perf``, which writes
where each matching kernel's ``*_cpu_forward`` entry was loaded; the samples' addresses, less the entry's offset in
the kernel's object file (``nm``), are offsets into that file's code. Printed per kernel: its share of the process's
samples, the hottest 64-byte and 1 KB stretches of its code (a flat profile has no stretch that matters alone), and
with ``--asm`` the instructions of the hottest stretches with their sample counts (``objdump``). Needs ``perf``,
``nm`` and ``objdump``.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile

_CHILD = "WARPWORM_KERNEL_SAMPLES_OUT"


def _child(path: str, images: int, repeats: int, out: str) -> None:
    """Replay the captured calls, then write {kernel: [entry address, object file]} of every loaded CPU kernel."""
    import ctypes
    import gc

    import job_render_replay as replay
    from warp._src.context import ModuleExec

    from warpworm import quiet_warp

    quiet_warp()
    replay.replay(path, images, repeats)
    found = {}
    for obj in gc.get_objects():
        if isinstance(obj, ModuleExec) and getattr(obj, "binary_path", None):
            for name, hooks in obj.kernel_hooks.items():
                if hooks.forward:
                    found[name] = [ctypes.cast(hooks.forward, ctypes.c_void_p).value, obj.binary_path]
    with open(out, "w") as f:
        json.dump(found, f)


def _entry_offset(obj_file: str, name: str) -> int:
    """Offset of ``<name>_cpu_forward`` in the object file's code section."""
    for line in subprocess.run(["nm", obj_file], capture_output=True, text=True, check=True).stdout.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2] == f"{name}_cpu_forward":
            return int(parts[0], 16)
    raise RuntimeError(f"{name}_cpu_forward not found in {obj_file}")


def _text_size(obj_file: str) -> int:
    """Bytes of the object file's code section (``.text``, or ``.ltext`` where LLVM used the large code model): the
    kernel's code, loaded in one piece (the bound that keeps another module's code, loaded next to it, out of the
    count)."""
    sizes = [int(parts[2], 16) for parts in (line.split() for line in subprocess.run(
        ["objdump", "-h", obj_file], capture_output=True, text=True, check=True).stdout.splitlines())
        if len(parts) > 2 and parts[1] in (".text", ".ltext")]
    if not sizes or max(sizes) == 0:
        raise RuntimeError(f"no code section in {obj_file}")
    return max(sizes)


def _stretches(hits: collections.Counter, width: int) -> collections.Counter:
    """Samples per ``width``-byte stretch of code (keyed by the stretch's first offset)."""
    out = collections.Counter()
    for off, k in hits.items():
        out[off // width * width] += k
    return out


def _report(name: str, address: int, obj_file: str, ips: list[int], top: int, asm: bool) -> None:
    base = address - _entry_offset(obj_file, name)
    size = _text_size(obj_file)
    hits = collections.Counter(ip - base for ip in ips if 0 <= ip - base < size)
    n = sum(hits.values())
    print(f"\n{name}: {n} of {len(ips)} samples ({100 * n / max(len(ips), 1):.1f} % of the process)")
    if not n:
        return
    hot = _stretches(hits, 64).most_common(top)
    for width, best in ((64, hot), (1024, _stretches(hits, 1024).most_common(3))):
        print(f"  hottest {width}-byte stretches: " + ", ".join(f"{off:#x} {100 * k / n:.1f} %" for off, k in best))
    if asm:
        starts = {off for off, _ in hot}
        for line in subprocess.run(["objdump", "-d", "--no-show-raw-insn", obj_file], capture_output=True, text=True,
                                   check=True).stdout.splitlines():
            m = re.match(r"\s*([0-9a-f]+):\s*(.*)", line)
            if m and int(m.group(1), 16) // 64 * 64 in starts:
                off = int(m.group(1), 16)
                print(f"  {hits.get(off, 0):5d} {off:#8x} {m.group(2)}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("path", help="calls captured by job_render_replay.py capture")
    parser.add_argument("--kernel", default="resolve_samples", help="report kernels whose name contains this")
    parser.add_argument("--images", type=int, default=64, help="the first call's first N images (0: all)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--top", type=int, default=12, help="64-byte stretches to list")
    parser.add_argument("--asm", action="store_true", help="print the hottest stretches' instructions")
    args = parser.parse_args(argv)
    if os.environ.get(_CHILD):
        _child(args.path, args.images, args.repeats, os.environ[_CHILD])
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        data, found = os.path.join(tmp, "perf.data"), os.path.join(tmp, "kernels.json")
        subprocess.run(["perf", "record", "-q", "-e", "cpu-clock", "-F", "4000", "-o", data, sys.executable,
                        os.path.abspath(__file__), args.path, "--images", str(args.images), "--repeats",
                        str(args.repeats)], env={**os.environ, _CHILD: found}, check=True)
        ips = [int(s, 16) for s in subprocess.run(["perf", "script", "-F", "ip", "-i", data], capture_output=True,
                                                  text=True, check=True).stdout.split()]
        with open(found) as f:
            kernels = json.load(f)
    chosen = {k: v for k, v in kernels.items() if args.kernel in k}
    if not chosen:
        print(f"--kernel: no loaded kernel's name contains {args.kernel!r}; loaded: {sorted(kernels)}")
        return 2
    for name, (address, obj_file) in sorted(chosen.items()):
        _report(name, address, obj_file, ips, args.top, args.asm)
    return 0


if __name__ == "__main__":
    sys.exit(main())
