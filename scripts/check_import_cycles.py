#!/usr/bin/env python3
"""Fails when the modules of a crate import each other in a circle.

For every crate root under crates/*/src (lib.rs, main.rs, bin/*.rs) the
module tree is followed through its `mod name;` declarations. An edge A -> B
is recorded when module A names an item of module B through a path that
starts with `crate::`, `super::` or `self::` (in `use` trees and inline in
code), or with the name of one of A's child modules. Edges to an ancestor
(a child using what its parent declares or re-exports, `crate::Item` from
lib.rs included) are not counted: the parent is the facade of its children.
Names re-exported by the crate root (`pub use a::Item;`) are resolved to the
module they come from. Test code (`#[cfg(test)] mod ... { }` blocks and
`#[cfg(test)] mod tests;` files) is left out.

Usage: scripts/check_import_cycles.py [ROOT]   (ROOT: the workspace, default .)
Exit status 1 and one line per cycle, with the file and line of each edge.
Python 3.11 standard library only.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
STRIP = re.compile(
    r"""//[^\n]*                       # line comment
      | /\*.*?\*/                      # block comment (not nested)
      | r(\#*)".*?"\1                  # raw string
      | b?"(?:\\.|[^"\\])*"            # string
      | b?'(?:\\.|[^'\\])'             # char literal (lifetimes do not match)
    """,
    re.S | re.X,
)
MOD_DECL = re.compile(rf"^[ \t]*(?:pub(?:\([^)]*\))?\s+)?mod\s+({IDENT})\s*;", re.M)
TEST_ATTR = re.compile(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(" + IDENT + r")\s*([;{])")
USE_STMT = re.compile(r"\buse\s+([^;]*);", re.S)
INLINE_PATH = re.compile(rf"\b((?:crate|super|self)(?:\s*::\s*{IDENT})+)")


def blank(text: str) -> str:
    """Comments and literals replaced by spaces (newlines kept, so lines stay)."""
    return STRIP.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def cut_test_blocks(code: str) -> tuple[str, set[str]]:
    """Removes inline `#[cfg(test)] mod x { ... }`; returns the code and the
    names of test modules declared as files (`#[cfg(test)] mod x;`)."""
    test_files: set[str] = set()
    out = []
    pos = 0
    for m in TEST_ATTR.finditer(code):
        if m.start() < pos:
            continue
        if m.group(2) == ";":
            test_files.add(m.group(1))
            continue
        depth, i = 0, m.end() - 1
        while i < len(code):
            if code[i] == "{":
                depth += 1
            elif code[i] == "}":
                depth -= 1
                if depth == 0:
                    break
            i += 1
        out.append(code[pos : m.start()])
        out.append(re.sub(r"[^\n]", " ", code[m.start() : i + 1]))
        pos = i + 1
    out.append(code[pos:])
    return "".join(out), test_files


def expand_use(tree: str) -> list[str]:
    """`a::{b, c::{d, e as f}, self}` -> ["a::b", "a::c::d", "a::c::e", "a"]."""
    tokens = re.findall(rf"{IDENT}|\{{|\}}|,|\*", tree)  # `::` carries no meaning here
    paths: list[str] = []

    def parse(i: int, prefix: list[str]) -> int:
        """One use tree from tokens[i]; returns the index after it."""
        segs = list(prefix)
        while i < len(tokens) and tokens[i] not in (",", "}"):
            t = tokens[i]
            if t == "{":
                i += 1
                while i < len(tokens) and tokens[i] != "}":
                    i = parse(i, segs)
                    if i < len(tokens) and tokens[i] == ",":
                        i += 1
                return i + 1
            if t == "as":
                i += 2
                continue
            if t not in ("*", "self") or not segs:
                segs.append(t)
            i += 1
        if segs:
            paths.append("::".join(segs))
        return i

    i = 0
    while i < len(tokens):
        i = parse(i, [])
        while i < len(tokens) and tokens[i] in (",", "}"):
            i += 1
    return paths


@dataclass
class Module:
    path: tuple[str, ...]
    file: Path
    children: set[str] = field(default_factory=set)
    # (target path as written, line)
    refs: list[tuple[list[str], int]] = field(default_factory=list)


def load_crate(root_file: Path) -> dict[tuple[str, ...], Module]:
    modules: dict[tuple[str, ...], Module] = {}

    def visit(file: Path, path: tuple[str, ...], child_dir: Path) -> None:
        code, test_files = cut_test_blocks(blank(file.read_text(encoding="utf-8")))
        module = Module(path, file)
        modules[path] = module
        for m in MOD_DECL.finditer(code):
            name = m.group(1)
            if name in test_files:
                continue
            for candidate, sub in (
                (child_dir / f"{name}.rs", child_dir / name),
                (child_dir / name / "mod.rs", child_dir / name),
            ):
                if candidate.exists():
                    module.children.add(name)
                    visit(candidate, path + (name,), sub)
                    break
        line_of = lambda pos: code.count("\n", 0, pos) + 1  # noqa: E731
        used = []
        for m in USE_STMT.finditer(code):
            for p in expand_use(m.group(1)):
                module.refs.append((p.split("::"), line_of(m.start())))
            used.append((m.start(), m.end()))
        for m in INLINE_PATH.finditer(code):
            if any(a <= m.start() < b for a, b in used):
                continue
            segs = [s.strip() for s in m.group(1).split("::")]
            module.refs.append((segs, line_of(m.start())))

    if root_file.name in ("lib.rs", "main.rs"):
        child_dir = root_file.parent
    else:  # src/bin/name.rs
        child_dir = root_file.parent / root_file.stem
    visit(root_file, (), child_dir)
    return modules


def root_reexports(modules: dict[tuple[str, ...], Module]) -> dict[str, tuple[str, ...]]:
    """`pub use a::b::Item;` in the crate root: Item -> (a, b)."""
    code = blank(modules[()].file.read_text(encoding="utf-8"))
    names: dict[str, tuple[str, ...]] = {}
    for m in re.finditer(r"\bpub\s+use\s+([^;]*);", code, re.S):
        for p in expand_use(m.group(1)):
            segs = [s for s in p.split("::") if s != "crate"]
            target = longest_module(modules, segs)
            if target:
                names[segs[-1]] = target
    return names


def longest_module(modules, segs: list[str]) -> tuple[str, ...] | None:
    best = None
    for n in range(1, len(segs) + 1):
        if tuple(segs[:n]) in modules:
            best = tuple(segs[:n])
        else:
            break
    return best


def resolve(modules, reexports, here: tuple[str, ...], segs: list[str]):
    if not segs:
        return None
    if segs[0] == "crate":
        absolute = segs[1:]
        if absolute and tuple(absolute[:1]) not in modules and absolute[0] in reexports:
            return reexports[absolute[0]]
    elif segs[0] in ("super", "self"):
        base = list(here)
        i = 0
        while i < len(segs) and segs[i] in ("super", "self"):
            if segs[i] == "super":
                if not base:
                    return None
                base.pop()
            i += 1
        absolute = base + segs[i:]
    elif segs[0] in modules[here].children:
        absolute = list(here) + segs
    else:
        return None
    return longest_module(modules, absolute)


def cycles_of(graph: dict[tuple, dict[tuple, int]]) -> list[list[tuple]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[tuple, int] = {}
    low: dict[tuple, int] = {}
    stack: list[tuple] = []
    on_stack: set[tuple] = set()
    found: list[list[tuple]] = []
    counter = [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(comp)

    sys.setrecursionlimit(10_000)
    for v in sorted(graph):
        if v not in index:
            strong(v)
    return found


def one_cycle(graph, comp: list[tuple]) -> list[tuple]:
    """A shortest circle through the component's first module (BFS)."""
    members = set(comp)
    start = min(comp)
    prev = {start: None}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v]):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return [start] + path[::-1][1:] + [start] if len(path) > 1 else [start, v, start]
            if w in members and w not in prev:
                prev[w] = v
                queue.append(w)
    return comp


def name(path: tuple[str, ...]) -> str:
    return "::".join(path) or "crate"


def check(workspace: Path) -> int:
    failures = 0
    roots = sorted(workspace.glob("crates/*/src/lib.rs")) + sorted(
        workspace.glob("crates/*/src/main.rs")
    ) + sorted(workspace.glob("crates/*/src/bin/*.rs"))
    for root_file in roots:
        modules = load_crate(root_file)
        reexports = root_reexports(modules)
        graph: dict[tuple, dict[tuple, int]] = {p: {} for p in modules}
        for here, module in modules.items():
            for segs, line in module.refs:
                target = resolve(modules, reexports, here, segs)
                if target is None or target == here or here[: len(target)] == target:
                    continue  # itself, or an ancestor
                graph[here].setdefault(target, line)
        label = root_file.relative_to(workspace)
        for comp in cycles_of(graph):
            circle = one_cycle(graph, comp)
            hops = ", ".join(
                f"{name(a)} -> {name(b)} ({modules[a].file.relative_to(workspace)}:{graph[a][b]})"
                for a, b in zip(circle, circle[1:])
            )
            print(f"{label}: import cycle {' -> '.join(map(name, circle))}: {hops}")
            if len(comp) > len(circle) - 1:
                print(f"  (modules in circles with each other: {', '.join(sorted(map(name, comp)))})")
            failures += 1
    if failures == 0:
        print(f"no import cycles in {len(roots)} crate roots")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(check(Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()))
