"""Every input known before any output (issue 33, item 1).

* Every option of every ``hyde-bsdf`` command, read from its argparse parser, is classified: it
  names files the run reads (marked by :func:`hyde_bsdf.app.args.reads`), files it writes
  (:func:`~hyde_bsdf.app.args.writes`), or it is not a file (a number, a flag, a choice, or a string
  listed in :data:`NOT_FILES`).  A new string option that is none of these fails here, so it cannot
  be forgotten.
* Each input option has a row in :data:`INPUT_CASES` in which an output of the run is that input:
  the command refuses it before any work (exit 2, "is the input"), and the file is unchanged.
* :func:`hyde_bsdf.io.scene_files.scene_files` lists what Mitsuba itself reads: for an include,
  a spectrum and a texture named in an included file, two candidate files in the two folders a
  resolver could look in hold different values; the value Mitsuba loads says which file it read,
  and that file (not the other) is in the list.

Cost: about 10 s (in-process refusals before any work; one scalar_rgb scene load).
"""
import argparse
import importlib
from pathlib import Path

import numpy as np
import pytest

from hyde_bsdf.app import cli
from hyde_bsdf.app.args import Parser

#: string options that name no file: (command, dest) -> what they are
NOT_FILES = {
    ("render", "variant"): "a Mitsuba variant", ("render", "define"): "NAME=VALUE of the scene",
    ("demo", "variant"): "a Mitsuba variant", ("export", "material"): "a Mitsuba data/ior name",
    ("export", "n"): "numbers", ("export", "k"): "numbers", ("export", "resolution"): "NxNxN",
    ("fit", "fit"): "parameter names", ("stokes", "angles"): "angles", ("stokes", "layout"): "angles",
    ("stokes", "retarder"): "angles", ("invert", "target"): "a key prefix", ("invert", "truth"): "values",
    ("invert", "start"): "values", ("invert", "fit"): "parameter names", ("invert", "tiles"): "N or RxC",
    ("invert", "scheduler"): "a network address", ("invert", "channel"): "a channel name",
    ("export", "diffuse_reflectance"): "numbers", ("export", "wavelengths"): "wavelengths or auto",
}


def _parsers():
    """(command, parser) of every command: its module's build_parser and *_parser functions."""
    for command, (module_name, _) in cli.COMMANDS.items():
        module = importlib.import_module(module_name)
        found = [getattr(module, n)() for n in dir(module) if n == "build_parser" or n.endswith("_parser")]
        found = [p for p in found if isinstance(p, argparse.ArgumentParser)]
        assert found, f"command {command}: no build_parser() in {module_name}"
        for parser in found:
            yield command, parser


def _options():
    """(command, dest, action) of every option but --help."""
    for command, parser in _parsers():
        for action in parser._actions:
            if not isinstance(action, argparse._HelpAction):
                yield command, action.dest, action


def _is_file_free(action) -> bool:
    """A flag, a number, a choice: cannot name a file."""
    return (action.nargs == 0 or action.choices is not None
            or (action.type is not None and action.type is not str))


def test_every_option_of_every_command_is_classified():
    unclassified = sorted({f"{command} {'/'.join(action.option_strings) or dest}"
                           for command, dest, action in _options()
                           if not (getattr(action, "reads", None) or getattr(action, "writes", False)
                                   or _is_file_free(action) or (command, dest) in NOT_FILES)})
    assert not unclassified, ("options that may name a file: mark them reads()/writes() (hyde_bsdf.app.args) "
                              f"or list them in NOT_FILES: {unclassified}")
    stale = sorted(set(NOT_FILES) - {(c, d) for c, d, _ in _options()})
    assert not stale, f"NOT_FILES names options that no longer exist: {stale}"


def _stokes_exr(path):
    import OpenEXR
    ch = {n: np.ones((4, 4), np.float32) for n in ("S0", "S1", "S2")}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, ch).write(str(path))


SCENE = ('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm"><integer name="width" '
         'value="4"/><integer name="height" value="4"/></film></sensor>{}</scene>')


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """The bytes of a small .pbsdf table (made once: a tabulation takes seconds)."""
    from hyde_bsdf.fit.pbsdf_export import export_pbsdf
    path = tmp_path_factory.mktemp("table") / "t.pbsdf"
    export_pbsdf(path, rms_slope=0.3, n=1.5, resolution=(4, 4, 4), progress=False)
    return path.read_bytes()


@pytest.fixture
def d(tmp_path, monkeypatch, table):
    """A folder with a scene whose <include> names out/alpha.exr (the issue's case), the files each
    input row uses, and the working folder there."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    _stokes_exr(tmp_path / "out" / "alpha.exr")
    (tmp_path / "bsdf.xml").write_text('<scene version="3.0.0"><bsdf type="hyde" id="b"><texture type="bitmap" '
                                       'name="alpha"><string name="filename" value="out/alpha.exr"/></texture>'
                                       '</bsdf></scene>')
    (tmp_path / "scene.xml").write_text(SCENE.format('<include filename="bsdf.xml"/><shape type="rectangle">'
                                                     '<ref id="b"/></shape>'))
    for name in ("m.exr", "c_intensity.png", "f1.exr", "a.exr", "ref.exr", "mask.npy", "cam.json", "light.json"):
        (tmp_path / "out" / name).write_bytes(b"an input of the run")
    (tmp_path / "scripts").mkdir()                       # a folder of validation scripts
    from hyde_bsdf.app.report.build import SECTIONS
    (tmp_path / "scripts" / f"{SECTIONS[0][1][0]}.py").write_text("# a validation script\n")
    (tmp_path / "dm").mkdir()                            # demo -o dm: its dm/demo.exr is the scene's texture
    (tmp_path / "dm" / "demo.exr").write_bytes((tmp_path / "out" / "alpha.exr").read_bytes())
    (tmp_path / "demo_bsdf.xml").write_text((tmp_path / "bsdf.xml").read_text().replace("out/alpha", "dm/demo"))
    (tmp_path / "demo.xml").write_text((tmp_path / "scene.xml").read_text().replace("bsdf.xml", "demo_bsdf.xml"))
    (tmp_path / "out" / "table.png").write_bytes(table)      # a .pbsdf under a plot's name
    return tmp_path


MAPS = ["invert", "--maps", "--scene", "scene.xml", "-o", "out"]
#: (command, dest) -> argv in which an output of the run is that input
INPUT_CASES = {
    ("render", "scene"): ["render", "scene.xml", "-o", "out/alpha.exr"],
    ("demo", "scene"): ["demo", "--scene", "demo.xml", "-o", "dm"],
    ("fit", "data"): ["fit", "out/table.png", "-o", "out/table.png"],
    ("stokes", "mosaic"): ["stokes", "--mosaic", "out/m.exr", "-o", "out/m.exr"],
    ("stokes", "frames"): ["stokes", "--frames", "out/a.exr", "out/f1.exr", "out/m.exr", "--angles", "0,60,120",
                           "-o", "out/f1.exr"],
    ("stokes", "analysis"): ["stokes", "--mosaic", "out/m.exr", "--analysis", "out/c_intensity.png", "--png",
                             "out/c", "-o", "out/o.exr"],
    ("invert", "scene"): MAPS + ["--reference", "out/ref.exr"],
    ("invert", "reference"): ["invert", "--reference", "out/invert.png", "-o", "out"],
    ("invert", "mask"): MAPS[:4] + ["--reference", "out/ref.exr", "--mask", "out/alpha_seen.npy", "-o", "out"],
    ("invert", "camera"): MAPS[:4] + ["--camera", "out/invert_maps_history.csv", "--light", "out/light.json",
                                      "--reference", "out/ref.exr", "-o", "out"],
    ("invert", "light"): MAPS[:4] + ["--camera", "out/cam.json", "--light", "out/invert_maps.png", "--reference",
                                     "out/ref.exr", "-o", "out"],
    ("invert", "tiles-camera"): MAPS[:4] + ["--camera", "out/invert_maps_history.csv", "--light", "out/light.json",
                                            "--reference", "out/ref.exr", "--tiles", "2", "-o", "out"],
    ("validate", "scripts"): ["validate", "-o", "scripts", "--scripts", "scripts", "--force"],
    ("export", "fit"): ["export", "out/fit.pbsdf", "--fit", "out/fit.pbsdf"],
}
#: files the rows name that do not exist yet (made as a copy of an input)
_MADE = {"out/invert.png": "out/ref.exr", "out/alpha_seen.npy": "out/mask.npy",
         "out/invert_maps_history.csv": "out/cam.json", "out/invert_maps.png": "out/light.json",
         "out/fit.pbsdf": "out/cam.json"}


#: commands that write no file (nothing an input could be replaced by): command -> what they do
WRITES_NOTHING = {"accuracy": "prints its answer"}


def test_every_input_option_has_a_case():
    marked = {(c, d) for c, d, a in _options() if getattr(a, "reads", None) and c not in WRITES_NOTHING}
    assert marked == {k for k in INPUT_CASES if k[1] != "tiles-camera"}, \
        "each option marked reads() needs a row in INPUT_CASES (and each row an option)"


@pytest.mark.parametrize("key", list(INPUT_CASES), ids=[f"{c} --{o}" for c, o in INPUT_CASES])
def test_an_output_that_is_an_input_is_refused_before_the_work(key, d, capsys):
    """The issue's cases among them: a texture named in an included file (was replaced by the
    fitted map), --camera named like the history CSV (was replaced, exit 0), the same with --tiles."""
    for made, source in _MADE.items():
        (d / made).write_bytes((d / source).read_bytes())
    before = {p: p.read_bytes() for p in d.rglob("*") if p.is_file()}
    code = cli.main(INPUT_CASES[key])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "is the input" in err, err
    assert {p: p.read_bytes() for p in d.rglob("*") if p.is_file()} == before


def test_scene_files_lists_what_mitsuba_reads(tmp_path, monkeypatch):
    """Mitsuba 3.9 resolves an include beside the including file first, a spectrum in an included
    file and a texture in an included file beside the *main* scene first, and a <path> folder before
    both; each pair of candidates holds different values, and the value loaded names the file read."""
    import mitsuba as mi

    from hyde_bsdf.io.scene_files import scene_files

    mi.set_variant("scalar_rgb")
    main, sub, extra = tmp_path / "main", tmp_path / "main" / "sub", tmp_path / "extra"
    for folder in (sub, extra):
        folder.mkdir(parents=True)
    monkeypatch.chdir(tmp_path)
    for folder, value in ((main, 0.25), (sub, 0.75)):
        mi.Bitmap(np.full((2, 2, 3), value, np.float32)).write(str(folder / "tex.exr"))
        (folder / "spec.spd").write_text(f"360 {value}\n830 {value}\n")
        (folder / "leaf.xml").write_text(f'<scene version="3.0.0"><bsdf type="diffuse" id="leaf"><rgb name='
                                         f'"reflectance" value="{value}"/></bsdf></scene>')
    mi.Bitmap(np.full((2, 2, 3), 0.5, np.float32)).write(str(extra / "only.exr"))
    (sub / "inc.xml").write_text(
        '<scene version="3.0.0"><bsdf type="diffuse" id="t"><texture type="bitmap" name="reflectance"><string '
        'name="filename" value="tex.exr"/></texture></bsdf><bsdf type="diffuse" id="s"><spectrum name="reflectance" '
        'filename="spec.spd"/></bsdf><include filename="leaf.xml"/></scene>')
    (main / "scene.xml").write_text(
        '<scene version="3.0.0"><path value="../extra"/><include filename="sub/inc.xml"/>'
        '<bsdf type="diffuse" id="o"><texture type="bitmap" name="reflectance"><string name="filename" '
        'value="only.exr"/></texture></bsdf>' + "".join(f'<shape type="sphere"><ref id="{i}"/></shape>'
                                                         for i in ("t", "s", "leaf", "o")) + "</scene>")
    params = mi.traverse(mi.load_file(str(main / "scene.xml")))
    loaded = {k.split(".")[0]: float(np.ravel(params[k])[0]) for k in params.keys()
              if k.endswith(("reflectance.data", "reflectance.value"))}
    assert loaded == pytest.approx({"t": 0.25, "s": 0.25, "leaf": 0.75, "o": 0.5}, abs=1e-3)
    files = {p.resolve() for p in scene_files(main / "scene.xml")}
    read = {main / "tex.exr", main / "spec.spd", sub / "leaf.xml", sub / "inc.xml", extra / "only.exr"}
    assert read <= files, read - files
    assert not {sub / "tex.exr", sub / "spec.spd", main / "leaf.xml"} & files
