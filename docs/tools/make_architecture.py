"""Draw docs/img/architecture.png: the package's parts in their layers and the import statements
between them, as a matrix (importer by imported, both in layer order), read from the
source as ``tests/test_layers.py`` reads it (every ``import``, the lazy ones inside functions too).

    .venv/bin/python docs/tools/make_architecture.py         # rewrite the picture
    .venv/bin/python docs/tools/make_architecture.py --text  # the counts only (no matplotlib)
"""
from __future__ import annotations

import ast
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "hyde_bsdf"
OUT = REPO / "docs" / "img" / "architecture.png"

#: column of each part (the layers of tests/test_layers.py); the infrastructure row sits under them all
COLUMN = {"io": 0, "model": 1, "mitsuba": 2, "mom": 2, "fit": 2, "render": 3, "inverse": 4, "app": 5,
          "validation": 6}
INFRASTRUCTURE = ("errors", "progress", "resources", "options")


def part_of(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0].removesuffix(".py")


def imported_parts(path: Path):
    """The parts of the package each import statement of ``path`` reaches."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    own_pkg = path.relative_to(PACKAGE).parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            mods = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = own_pkg[:len(own_pkg) - node.level + 1]
                mods = [".".join(("hyde_bsdf",) + base + ((node.module,) if node.module else ()))]
            else:
                mods = [node.module or ""]
            if mods == ["hyde_bsdf"]:
                mods = [f"hyde_bsdf.{a.name}" for a in node.names]
        else:
            continue
        for m in mods:
            parts = m.split(".")
            if parts[0] == "hyde_bsdf" and len(parts) > 1:
                yield parts[1]


def graph():
    """(lines per part, Counter of (importer, imported) import statements between different parts)."""
    lines, edges = Counter(), Counter()
    for path in sorted(PACKAGE.rglob("*.py")):
        if "__pycache__" in path.parts or path == PACKAGE / "__init__.py":
            continue
        own = part_of(path)
        lines[own] += len(path.read_text(encoding="utf-8").splitlines())
        for target in imported_parts(path):
            if target != own and (target in COLUMN or target in INFRASTRUCTURE):
                edges[own, target] += 1
    return lines, edges


def positions():
    pos = {}
    for col in range(max(COLUMN.values()) + 1):
        names = [n for n, c in COLUMN.items() if c == col]
        for i, n in enumerate(names):
            pos[n] = (col * 2.2, 2.4 + (i - (len(names) - 1) / 2) * 1.5)
    for i, n in enumerate(INFRASTRUCTURE):
        pos[n] = (3.0 + i * 2.4, -0.6)
    return pos


def draw(lines, edges, out=OUT):
    """The import matrix: a row per importing part, a column per imported part, both in layer order; a
    cell holds the import statements.  Allowed imports lie left of the diagonal, so an empty right
    half is the layering rule, seen at once."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(COLUMN) + list(INFRASTRUCTURE)
    counts = np.array([[edges[a, b] for b in names] for a in names], float)
    fig, ax = plt.subplots(figsize=(9.5, 6.2))
    ax.imshow(np.log1p(counts), cmap="Blues", vmin=0, vmax=np.log1p(counts.max()) * 1.3)
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            forbidden = a not in INFRASTRUCTURE and b in COLUMN and COLUMN[b] >= COLUMN[a] and a != b
            if a == b or (a in INFRASTRUCTURE and b != "errors"):
                forbidden = a != b
            if forbidden:
                ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fc="#f2f2f2", ec="none"))
            if counts[i, j]:
                ax.text(j, i, f"{int(counts[i, j])}", ha="center", va="center", fontsize=9,
                        color="#b00000" if forbidden else "black")
            elif a == b:
                ax.text(j, i, "·", ha="center", va="center", color="#999999")
    ax.set_xticks(range(len(names)), names, rotation=40, ha="right")
    ax.set_yticks(range(len(names)), [f"{n}  ({lines[n]} lines)" for n in names])
    ax.axhline(len(COLUMN) - 0.5, color="#777777", lw=0.8)
    ax.axvline(len(COLUMN) - 0.5, color="#777777", lw=0.8)
    ax.set_xlabel("imported part (layers left to right: files, physics, ..., command line; then the small core)")
    ax.set_ylabel("importing part")
    ax.set_title("hyde_bsdf: import statements between parts (grey: forbidden by the layering; "
                 "mitsuba, mom, fit side by side)", fontsize=9)
    fig.tight_layout()
    tmp = out.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(out)
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    lines, edges = graph()
    if "--text" in argv:
        for name in list(COLUMN) + list(INFRASTRUCTURE):
            print(f"{name:11s} {lines[name]:6d} lines  imports " + ", ".join(
                f"{b} x{n}" for (a, b), n in sorted(edges.items()) if a == name))
        return 0
    print(f"wrote {draw(lines, edges).relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
