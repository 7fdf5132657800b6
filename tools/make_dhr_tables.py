"""Write the DHR tables the package ships in ``hyde_bsdf/data/`` (model/dhr.py, "Shipped as data").

For every shadowing record of ``hyde_bsdf.model.terms``: rho^{s,PEC} on the table's grid by the
slope-space quadrature (``dhr.build_table``, the record's Gauss-Legendre order), float64, into
``dhr_table.npz``; and the plugin's 1 - rho texture resampled from it (``dhr.texture_from_table``,
float32, stored as exact second differences of its bit patterns) into ``dhr_texture_{vgroove,smith,none}.npz``.
Run it after changing the quadrature, the grid, the texture's resolution or a shadowing record;
``tests/test_dhr_table.py`` recomputes a sample of nodes and texels from the shipped files.
About 15 s on 2 cores.

    .venv/bin/python tools/make_dhr_tables.py
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from hyde_bsdf.model import dhr
from hyde_bsdf.model.terms import SHADOWING_TERMS

DATA = Path(__file__).resolve().parent.parent / "hyde_bsdf" / "data"


def _write(path: Path, **arrays) -> None:
    """np.savez_compressed into a temporary file in the same folder, then renamed over ``path``."""
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")


def main() -> int:
    DATA.mkdir(exist_ok=True)
    table_arrays, meta = {}, {"generator": "tools/make_dhr_tables.py", "orders": {}}
    for term in SHADOWING_TERMS:
        t0 = time.perf_counter()
        table = dhr.build_table(term.name, progress=False)
        print(f"{term.name}: table {table.rho.shape} in {time.perf_counter() - t0:.1f} s")
        table_arrays["x"], table_arrays["log_slope"] = table.x, table.log_slope
        table_arrays[f"{term.name}_rho"], table_arrays[f"{term.name}_rho_avg"] = table.rho, table.rho_avg
        meta["orders"][term.name] = list(term.dhr_order)
        tex = dhr.texture_from_table(table)
        _write(DATA / dhr.TEXTURE_FILE.format(term.name), log_range=np.array([tex.log_lo, tex.log_hi]),
               one_minus_d2=dhr.encode_texture_values(tex.one_minus), one_minus_avg=tex.one_minus_avg)
    _write(DATA / dhr.TABLE_FILE, meta=np.array(json.dumps(meta)), **table_arrays)
    return 0


if __name__ == "__main__":
    sys.exit(main())
