"""Walk the dataset path as a reader follows it and count the returns to a module already left.

Usage::

    python3 benchmarks/data_path_walk.py [--config default] [--num 2] [--list]

Runs ``warpworm generate CONFIG`` (the command's ``_generate``, one worker, in this process) under a profile hook and
builds its call tree over the data-path modules (``warpworm.commands.generate``, ``warpworm.data.*``, ``warpworm.rng``):
every function once, its callees in the order first called. Walking that tree depth-first, a function's first call
into another data-path module is a *visit* (its further calls into that module read on in the same place); a visit to
a module that the walk has entered before and left is a *return*. Calls
into the simulator, the renderer and the physics are leaves (not followed). A path that flows one way (plan -> draw ->
simulate -> render -> write) has few returns; a shard that asks for its draws piece by piece has many.

Module bodies run before the walk (it follows calls, not imports); returns into the leaf libraries (:data:`LIBRARIES`:
the RNG, the distributions) are also reported apart. Prints the modules
visited, the visit sequence's length and the returns (``--list``: each return outside the libraries, with its call).
Run it on another tree with ``PYTHONPATH=OTHER_TREE``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import types
from pathlib import Path

PATH_PREFIXES = ("warpworm.commands.generate", "warpworm.data", "warpworm.rng")


PACKAGES = ("warpworm.data.config", "warpworm.data.dataset")
"""Packages counted as one module each (their files split one topic's code, the reader still visits one place)."""


def _in_path(module: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in PATH_PREFIXES)


def _module(module: str) -> str:
    for p in PACKAGES:
        if module.startswith(p + "."):
            return p
    return module


VALUE_TYPES = ("DatasetConfig", "Summary", "ShardStats", "Draws", "WorldDraws", "RenderDraws")
"""Value objects handed along the path: reading one (its accessors) is reading what one was given."""


def _reads_data(fn: tuple) -> bool:
    """A call that reads a value object handed along (:data:`VALUE_TYPES`, a container's dunder methods, a
    dataclass's generated ``__init__``): reading what one was given, not asking back."""
    qual = fn[1]
    return (qual.split(".", 1)[0] in VALUE_TYPES or qual.rsplit(".", 1)[-1].startswith("__")
            or "__create_fn__" in qual)


def trace_generate(config: str, num: int, out: Path) -> dict:
    """Run the generate command with a profile hook; returns {caller: [callees in first-call order]} over functions
    (module, qualname) of the data path (callees outside it are kept as leaves)."""
    import importlib

    from warpworm.commands import generate as gen

    for name in ("warpworm.data.config", "warpworm.data.dataset", "warpworm.data.job", "warpworm.data.stages",
                 "warpworm.data.warp_stages", "warpworm.data.workers", "warpworm.data.previews"):
        try:
            importlib.import_module(name)  # module bodies run before the walk: it follows calls, not imports
        except ModuleNotFoundError:  # an older tree without it
            pass
    children: dict[tuple, list] = {}
    seen_edges: set = set()

    def key(frame):
        return (frame.f_globals.get("__name__", "?"), frame.f_code.co_qualname)

    def hook(frame, event, arg):
        if event != "call":
            return
        callee = key(frame)
        if not callee[0].startswith("warpworm"):
            return
        caller_frame = frame.f_back
        while caller_frame is not None and not _in_path(key(caller_frame)[0]):
            caller_frame = caller_frame.f_back  # the nearest data-path function on the stack
        if caller_frame is None:
            return
        caller = key(caller_frame)
        if (caller, callee) not in seen_edges:
            seen_edges.add((caller, callee))
            children.setdefault(caller, []).append(callee)

    args = types.SimpleNamespace(config=config, overrides=[], num=num, seed=7, print_config=False, workers=1,
                                 engine="local", address=None, resume=False, stages=None, no_progress=True,
                                 no_preview=True, out=str(out))
    sys.setprofile(hook)
    try:
        rc = gen._generate(args, ["job"])
    finally:
        sys.setprofile(None)
    if rc != 0:
        raise SystemExit(f"generate failed (exit {rc})")
    return children


LIBRARIES = frozenset({"warpworm.rng", "warpworm.data.randomize", "warpworm.data.export_json",
                       "warpworm.data.signal_hold"})
"""Leaf libraries of the path (the RNG, the distributions, JSON conversion, the signal hold around HDF5 calls): called
from anywhere, they call back nowhere; returns into them are reported apart."""


def walk(children: dict, root: tuple, skip: set[str] = frozenset()) -> tuple[list[str], list[tuple]]:
    """Depth-first over the call tree from ``root`` (each function expanded once), calls into ``skip`` modules left
    out: (module visit sequence, returns as (caller, callee))."""
    visits: list[str] = [_module(root[0])]
    entered: set[str] = {_module(root[0])}
    returns: list[tuple] = []
    expanded: set[tuple] = set()
    seen: set[tuple] = set()  # (function, module) pairs visited

    def go(fn):
        if fn in expanded:
            return
        expanded.add(fn)
        for c in children.get(fn, []):
            if not _in_path(c[0]) or _reads_data(c) or _module(c[0]) in skip:
                continue
            m, here = _module(c[0]), _module(fn[0])
            if m != here and (fn, m) not in seen:
                seen.add((fn, m))
                visits.append(m)
                if m in entered:
                    returns.append((fn, c))
                entered.add(m)
            go(c)
            if m != here:
                visits.append(here)  # back in the caller's module

    go(root)
    return visits, returns


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="default")
    ap.add_argument("--num", type=int, default=2)
    ap.add_argument("--list", action="store_true", help="print each return with its call")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        children = trace_generate(a.config, a.num, Path(tmp) / "out")
    root = ("warpworm.commands.generate", "_generate")
    leaves = set(LIBRARIES)
    visits, returns = walk(children, root)
    _, returns_no_leaves = walk(children, root, skip=leaves)
    modules = sorted(set(visits))
    print(f"modules visited: {len(modules)}: {', '.join(m.removeprefix('warpworm.') for m in modules)}")
    print(f"visits: {len(visits)}; returns to a module already left: {len(returns)}; "
          f"not counting calls into the leaf libraries: {len(returns_no_leaves)}")
    if a.list:
        for fn, c in returns_no_leaves:
            print(f"  {fn[0]}.{fn[1]} -> {c[0]}.{c[1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
