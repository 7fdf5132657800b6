"""Package set-up: import without Mitsuba, the LLVM guard, roughness conversions, CLI dispatch."""
import math
import subprocess
import sys
import warnings

import pytest

import hyde_bsdf
from hyde_bsdf.model import roughness
from hyde_bsdf.mitsuba import variants


def test_import_does_not_import_mitsuba():
    code = "import sys, hyde_bsdf; assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_roughness_conversions():
    """Paper: rms slope sqrt(2) sigma_h / l; Beckmann alpha = 2 sigma_h / l = sqrt(2) rms slope."""
    s = hyde_bsdf.rms_slope_from(3.0, 10.0)
    assert s == pytest.approx(math.sqrt(2) * 0.3)
    assert roughness.alpha_from_rms_slope(s) == pytest.approx(2 * 3.0 / 10.0)
    assert roughness.rms_slope_from_alpha(0.6) == pytest.approx(0.6 / math.sqrt(2))
    with pytest.raises(ValueError, match="sigma_h"):
        hyde_bsdf.rms_slope_from(-1.0, 10.0)
    with pytest.raises(ValueError, match="ell"):
        hyde_bsdf.rms_slope_from(1.0, 0.0)


def test_old_llvm_falls_back_to_scalar_with_a_message(monkeypatch):
    """Dr.Jit 1.5 aborts the process with libLLVM 15: we must never select llvm_* then."""
    import drjit
    monkeypatch.setattr(drjit.detail, "llvm_version", lambda: (15, 0, 7))
    with pytest.warns(RuntimeWarning, match="libLLVM 15.0.7"):
        assert variants.usable_variant("llvm_ad_spectral_polarized") == "scalar_spectral_polarized"
    with pytest.raises(variants.VariantUnavailable, match="version >= 16"):
        variants.usable_variant("llvm_ad_rgb", fallback=False)


def test_missing_llvm_falls_back(monkeypatch):
    import drjit

    def boom():
        raise RuntimeError("libLLVM not found")
    monkeypatch.setattr(drjit.detail, "llvm_version", boom)
    with pytest.warns(RuntimeWarning, match="no libLLVM"):
        assert variants.usable_variant("llvm_ad_rgb") == "scalar_rgb"


def test_current_llvm_is_usable_here():
    """The set-up (run.sh) installs libLLVM >= 16; on such a machine the LLVM variants are kept."""
    ok, why = variants.llvm_usable()
    assert ok, why
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert variants.usable_variant("llvm_ad_spectral_polarized") == "llvm_ad_spectral_polarized"


def test_unknown_variant_is_refused():
    with pytest.raises(variants.VariantUnavailable, match="variant='llvm_ad_nonsense'"):
        variants.usable_variant("llvm_ad_nonsense")


def test_cli_lists_commands():
    out = subprocess.run([sys.executable, "-m", "hyde_bsdf.app.cli", "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    for cmd in ("demo", "render", "fit", "invert", "validate"):
        assert cmd in out.stdout


def test_the_wheel_carries_every_file_of_the_package():
    """Issue 34 item 6: ``pip install`` of the wheel is enough -- it carries the data tables, the
    scenes and the validation scripts.  setuptools puts into the wheel the ``.py`` files of every
    package (a folder with ``__init__.py``: pyproject's ``packages.find``) and the files that
    pyproject's ``package-data`` patterns name; any other file of ``hyde_bsdf/`` would be missing
    after ``pip install``.  (CI builds, installs and runs the wheel itself: tools/check_wheel.sh.)"""
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    package = root / "hyde_bsdf"
    setup = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert setup["packages"]["find"]["include"] == ["hyde_bsdf*"]
    files = {p for p in package.rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    code = {p for p in files if p.suffix == ".py"
            and all((d / "__init__.py").is_file() for d in [p.parent, *p.parent.parents] if package in [d, *d.parents])}
    data = {p for pattern in setup["package-data"]["hyde_bsdf"] for p in package.glob(pattern) if p.is_file()}
    assert sorted(str(p.relative_to(root)) for p in files - code - data) == []
    needed = [package / "data" / name for name in ("dhr_table.npz", "accuracy_atlas.npz")] + \
        [package / "data" / "scenes" / "demo.xml", package / "validation" / "_common.py"]
    assert [str(p.relative_to(root)) for p in needed if p not in code | data] == []
