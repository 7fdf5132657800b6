"""The bad-input matrix (issue 10): every user mistake ends in one line that names the parameter or
file, exit status 2 on the command line, and no Python traceback; nothing is rendered or fitted
before the output paths and the scene have been checked.

``CLI_ROWS`` is one list of tuples ``(id, argv, exit_code, needle, how)``:

* ``argv``: the ``hyde-bsdf`` arguments; ``{name}`` is filled from the ``paths`` fixture below
  (``tmp``, ``file`` (a regular file), ``tiny`` (a small valid scene), ``nosensor``, ``ptracer``,
  ``inverse`` (hyde_bsdf/data/scenes/inverse.xml), ``csv`` (a Mueller-measurement CSV), ``notreport``
  (a folder with a user's file in it));
* ``needle``: a piece of the last stderr line (it names the parameter or file);
* ``how``: ``"in"`` runs ``hyde_bsdf.app.cli.main`` in this process; ``"sub"`` runs
  ``python -m hyde_bsdf.app.cli`` (where a crash or signal is the point); ``"lowmem"`` is ``"in"``
  with ``MemAvailable`` read as 2 GiB (``"mem8m"``: 8 MiB); ``"noscripts"`` is ``"in"`` with the validation scripts'
  folder missing; ``"sigint"`` sends Ctrl-C once the render's progress line appears;
  ``"sighup"`` sends SIGHUP there, ``"sigint-group"`` Ctrl-C to the run's whole process group (as a
  terminal does); ``"pipe"`` closes the reader of stdout at once (``hyde-bsdf fit ... | head -0``);
  ``"cuda"`` is ``"in"``, run only on a machine without a CUDA GPU (hardware-dependent);
  ``"diskfull"`` is ``"in"`` with every file system reporting 50 KB free and a render pass failing
  the test (so a refusal proves the free space was checked before the first pass); ``"noscene"`` is
  ``"in"`` with loading a scene failing the test (refused before any scene loads);
  ``"server-MODE"`` is ``"in"`` with ``{server}`` a local port that is no dask scheduler
  (:class:`_HostileServer`) and ``HYDE_BSDF_CONNECT_TIMEOUT=0.5``; ``"tasklimit"`` is ``"in"`` with
  ``HYDE_BSDF_TASK_TIMEOUT=0.01``.

Append a row for each new mistake; ``API_ROWS`` does the same for Python calls
``(id, call(paths), exception type, needle)``.
"""
import contextlib
import errno
import os
import shutil
import signal
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from conftest import scaled

from hyde_bsdf.app import cli
from hyde_bsdf.io.atomic import TEMP_NAME_RE
from hyde_bsdf.errors import UsageError

ROOT = Path(__file__).resolve().parent.parent

SCENE = """<scene version="3.0.0">
    <default name="spp" value="4"/>
    <default name="res" value="12"/>
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, -4, 1" target="0, 0, 0.3" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
    <emitter type="constant"/>
</scene>
"""

CLI_ROWS = [
    # --- render: output paths, checked before the render ---
    ("render: scene missing", ["render", "{tmp}/missing.xml", "-o", "{tmp}/a.exr"], 2, "scene file", "in"),
    ("render: output not .exr", ["render", "{tiny}", "-o", "{tmp}/a.png"], 2, "--output must end in .exr", "in"),
    ("render: output under a regular file", ["render", "{tiny}", "-o", "{file}/a.exr"], 2, "is not a directory", "in"),
    ("render: output in /proc", ["render", "{tiny}", "-o", "/proc/hyde.exr"], 2, "cannot write in '/proc'", "in"),
    ("render: output is a directory", ["render", "{tiny}", "-o", "{tmp}/dir.exr"], 2, "is a directory", "in"),
    ("render: a PNG path is a directory", ["render", "{tiny}", "-o", "{tmp}/pngdir.exr"], 2,
     "pngdir_dolp.png' is a directory", "in"),
    # --- render: scene sanity ---
    ("render: no sensor", ["render", "{nosensor}", "-o", "{tmp}/a.exr"], 2, "has no <sensor>", "in"),
    # Mitsuba re-raises the plugin's UsageError (a ValueError) with its traceback inside the message: one line is left
    ("render: bad hyde parameter in the scene", ["render", "{badhyde}", "-o", "{tmp}/a.exr"], 2,
     "UsageError: hyde: rms_slope must be a finite number in the accepted range [0.0001, 50]", "in"),
    ("render: ptracer integrator", ["render", "{ptracer}", "-o", "{tmp}/a.exr"], 2, "integrator 'ptracer'", "in"),
    ("render: sample_count 0 (was SIGFPE)", ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "spp=0"], 2,
     "sample_count is 0; it must be an integer >= 1 (the scene's $spp; set it with -D spp=N)", "sub"),
    ("render: film width 0", ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "res=0"], 2,
     "film width is 0; it must be an integer >= 1", "in"),
    ("render: film beyond Dr.Jit's array limit", ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "res=20000"],
     2, "film is too large", "in"),
    ("render: memory estimate above MemAvailable",
     ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "res=5000", "--spp", "1"], 2,
     "2 GiB is available; lower the film's width and height (the scene's $res; set it with -D res=N)",
     "lowmem"),
    ("render: spp beyond 2^16 passes", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--spp", "100000000000"], 2,
     "lower --spp to <=", "in"),
    ("render: spp 0", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--spp", "0"], 2, "--spp: expected an integer >= 1", "in"),
    ("render: seed out of range", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--seed", "40000"], 2,
     "seed must be an integer in [0, 32767]", "in"),
    ("render: chunks above spp", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--spp", "2", "--chunks", "5"], 2,
     "chunks must be an integer in [1, 2]", "in"),
    ("render: bad -D", ["render", "{tiny}", "-o", "{tmp}/a.exr", "-D", "noequals"], 2, "-D expects name=value", "in"),
    ("render: -D of an unknown name", ["render", "{tiny}", "-o", "{tmp}/a.exr", "-D", "nosuch=3"], 2,
     "unused parameters", "in"),
    ("render: unknown variant", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--variant", "llvm_ad_rgbx"], 2,
     "variant must be one of", "in"),
    ("render: cuda variant without a GPU", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--variant", "cuda_ad_rgb"], 2,
     "needs a CUDA GPU", "cuda"),
    ("render: Ctrl-C", ["render", "{tiny}", "-o", "{tmp}/sigint.exr", "--spp", "200000", "--chunks", "20000"], 130,
     "hyde-bsdf render: interrupted", "sigint"),
    # --- demo ---
    ("demo: outdir is a regular file", ["demo", "-o", "{file}"], 2, "is a regular file, not a folder", "in"),
    ("demo: outdir under a regular file", ["demo", "-o", "{file}/sub"], 2, "cannot create the folder", "in"),
    ("demo: outdir in /proc", ["demo", "-o", "/proc/hyde_demo"], 2, "'/proc/hyde_demo'", "in"),
    ("demo: scene missing", ["demo", "-o", "{tmp}/d", "--scene", "{tmp}/none.xml"], 2, "demo scene", "in"),
    ("demo: bad width", ["demo", "-o", "{tmp}/d", "--width", "0"], 2, "--width: expected an integer >= 1", "in"),
    # --- validate ---
    ("validate: outdir is a regular file", ["validate", "-o", "{file}"], 2, "is a regular file", "in"),
    ("validate: outdir under a regular file", ["validate", "-o", "{file}/r"], 2, "is a regular file", "in"),
    ("validate: outdir is a user's folder", ["validate", "-o", "{notreport}"], 2, "is not a validation report", "in"),
    ("validate: outdir is the current folder", ["validate", "-o", "."], 2, "is the current folder", "in"),
    ("validate: the package's scripts are missing (an incomplete install)", ["validate", "-o", "{tmp}/r"], 2,
     "validation scripts are missing", "noscripts"),
    ("validate: --scripts names a folder without the scripts (new)", ["validate", "-o", "{tmp}/r", "--scripts",
     "{tmp}"], 2, "holds none of the validation scripts", "in"),
    # --- fit (output path checked before the fit) ---
    ("fit: -o is a directory", ["fit", "{csv}", "-o", "{tmp}"], 2, "is a directory", "in"),
    ("fit: -o under a regular file", ["fit", "{csv}", "-o", "{file}/plot.png"], 2, "is not a directory", "in"),
    ("fit: stdout closed (| head)", ["fit", "{csv}"], 141, "", "pipe"),
    # --- issue 15: nothing lost, ever (every row also checks that no existing file changed) ---
    ("validate: outdir is a web site (an index.html the report did not write)", ["validate", "-o", "{site}"], 2,
     "is not a validation report and holds 2 file(s) ('index.html', 'style.css')", "in"),
    ("render: disk full writing the EXR (the old one kept)", ["render", "{tiny}", "-o", "{full}/a.exr"], 2,
     "a.exr': No space left on device; the earlier file is unchanged", "enospc@1"),
    ("fit: disk full writing the plot", ["fit", "{csv}", "-o", "{full}/plot.png"], 2,
     "plot.png': No space left on device; the earlier file is unchanged", "enospc@1"),
    ("render: output names too long for the file system (refused before the render)",
     ["render", "{tiny}", "-o", "{tmp}/" + "x" * 246 + ".exr"], 2,
     "_intensity.png': the name is 260 bytes, longer than the 255 bytes the file system allows", "in"),
    ("fit: -o name too long for the file system", ["fit", "{csv}", "-o", "{tmp}/" + "p" * 300 + ".png"], 2,
     ".png': the name is 304 bytes, longer than the 255 bytes the file system allows", "in"),
    ("render: SIGTERM removes the temporaries", ["render", "{tiny}", "-o", "{tmp}/sigterm.exr", "--spp", "200000",
     "--chunks", "20000"], 143, "hyde-bsdf render: terminated (SIGTERM)", "sigterm"),
    ("render: a killed run's temporaries are removed by the next run", ["render", "{tmp}/missing.xml", "-o",
     "{stale}/a.exr"], 2, "scene file", "stale"),
    # --- issue 15: fit statistics and files that tell the truth ---
    ("fit: CSV with old-Mac CR line ends (the bad cell's line is named)", ["fit", "{crcsv}"], 2,
     "crlines.csv, line 4, column 'M01': 'x' is not a number", "in"),
    ("fit: 1000 copies of 3 rows (errors of 3 rows)", ["fit", "{copies}", "-q"], 0,
     "2997 of 3000 rows repeat another row's geometry", "in"),
    # issue 30: a value is judged against its own sigma; -1.3 +- 0.0018 is impossible: refused, naming the line
    ("fit: impossible data, |M22/M00| > 1 far beyond its sigma", ["fit", "{impossible}", "-q"], 2,
     "impossible.csv, line 3, column 'M22': -1.3 is not a normalized element", "in"),
    # --- invert (issue 15: a reference scaled by 1e30 ended in a drjit.backward traceback) ---
    ("invert: reference scaled by 1e30", ["invert", "--reference", "{ref1e30}", "--res", "16", "-o", "{tmp}/kept"], 2,
     "ref1e30.exr' has peak |S0| = 1e+30, outside the accepted range [1e-10, 1e+10]", "in"),
    # --- issue 15: plugin values checked as Mitsuba evaluates them (the scene is checked before the render) ---
    ("render: eta bitmap with a negative texel (was accepted: furnace 1.99)", ["render", "{negeta}", "-o",
     "{tmp}/negeta_out.exr"], 2, "hyde: parameter 'eta' must be finite and in [0, 1e+06] (index n + i k with k >= 0), "
     "got eta.data texel value -1.5", "in"),
    ("render: eta = 1e10 (was an all-NaN image)", ["render", "{hugeeta}", "-o", "{tmp}/hugeeta.exr"], 2,
     "hyde: parameter 'eta' must be finite and in [0, 1e+06]", "in"),
    ("render: an 8-bit PNG alpha map loads (was refused: 'alpha.data = 83.0')", ["render", "{png8}", "-o",
     "{tmp}/png8.exr", "--variant", "llvm_ad_mono_polarized"], 0, "png8.exr", "in"),
    ("render: alpha = 0 renders as the lower bound, like roughconductor (was refused)", ["render", "{alpha0}", "-o",
     "{tmp}/alpha0.exr"], 0, "alpha0.exr", "in"),
    # --- dispatcher ---
    ("unknown command", ["nosuch"], 2, "unknown command 'nosuch'", "in"),
    # --- issue 24: the output gate (an existing target that is not a regular file is never replaced) ---
    ("render: -o is a FIFO (was replaced by a file, exit 0)", ["render", "{tiny}", "-o", "{tmp}/out_fifo.exr"], 2,
     "out_fifo.exr' exists and is a FIFO (named pipe), not a regular file: not replaced", "in"),
    ("render: -o is a symlink into /proc/self/fd (was replaced)", ["render", "{tiny}", "-o", "{tmp}/link_fd.exr"],
     2, "link_fd.exr' is a symbolic link to", "in"),
    ("render: -o is a symlink up out of its folder (new)", ["render", "{tiny}", "-o", "{tmp}/sub/link_up.exr"], 2,
     "outside its folder: not replaced", "in"),
    ("render: -o is a socket (new)", ["render", "{tiny}", "-o", "{tmp}/sock.exr"], 2,
     "sock.exr' exists and is a socket, not a regular file", "in"),
    ("render: a PNG of the set is a FIFO (new)", ["render", "{tiny}", "-o", "{tmp}/b.exr"], 2,
     "b_dolp.png' exists and is a FIFO (named pipe)", "in"),
    ("fit: -o plot is a FIFO (new)", ["fit", "{csv}", "-o", "{tmp}/plot_fifo.png"], 2,
     "plot_fifo.png' exists and is a FIFO", "in"),
    ("export: the .pbsdf output is /dev/null (new: a device)", ["export", "/dev/null", "--rms-slope", "0.3",
     "--n", "1.5"], 2, "'/dev/null' exists and is a character device, not a regular file: not replaced", "in"),
    # --- issue 24: the input gate (regular files or '-', never a FIFO or a device; size and field limits) ---
    ("fit: the CSV is a FIFO (was a hang)", ["fit", "{tmp}/pipe.csv"], 2,
     "pipe.csv' is a FIFO (named pipe), not a regular file; give a file, or '-' to read standard input", "in"),
    ("fit: /dev/zero (was unbounded memory)", ["fit", "/dev/zero"], 2,
     "'/dev/zero' is a character device, not a regular file", "in"),
    ("fit: /dev/urandom (new)", ["fit", "/dev/urandom"], 2, "'/dev/urandom' is a character device", "in"),
    ("fit: the CSV is a socket (new)", ["fit", "{tmp}/sock.csv"], 2, "sock.csv' is a socket, not a regular file", "in"),
    ("fit: the CSV is a folder (new)", ["fit", "{tmp}/kept"], 2, "kept' is a directory, not a regular file", "in"),
    ("fit: a 200 KB cell (was a traceback)", ["fit", "{tmp}/bigcell.csv"], 2,
     "bigcell.csv, line 3: a field is longer than the 4096 characters accepted", "in"),
    ("fit: a 200 KB header name (new)", ["fit", "{tmp}/bighead.csv"], 2,
     "bighead.csv, line 1: a field is longer than the 4096 characters accepted", "in"),
    ("render: a bitmap texture that is a FIFO (was a hang)", ["render", "{fifotex}", "-o", "{tmp}/ft.exr"], 2,
     "tex_fifo.png' is a FIFO (named pipe), not a regular file; give a file", "in"),
    ("render: a bitmap texture that is /dev/zero (new)", ["render", "{devtex}", "-o", "{tmp}/dt.exr"], 2,
     "file '/dev/zero' is a character device", "in"),
    ("render: the scene is a FIFO (new)", ["render", "{tmp}/scene_fifo.xml", "-o", "{tmp}/sf.exr"], 2,
     "scene file", "in"),
    # --- issue 24: material names are Mitsuba's data/ior names only, in the plugin as in export ---
    ("export: material escaping data/ior with ../", ["export", "{tmp}/m.pbsdf", "--rms-slope", "0.3",
     "--material", "../../../../etc/passwd"], 2, "material '../../../../etc/passwd' is not one of Mitsuba's data/ior", "in"),
    ("export: a 100 KB material name is cut in the message", ["export", "{tmp}/m.pbsdf", "--rms-slope", "0.3",
     "--material", "A" * 100_000], 2, "characters]...AAAAAAAAAAAAAAAAAAAAAAAA' is not one of Mitsuba's data/ior tables", "in"),
    ("render: the plugin's material with ../ (was followed out of data/ior)", ["render", "{dotdotmat}", "-o",
     "{tmp}/dm.exr"], 2, "hyde: material '../ior/Au' is not one of Mitsuba's data/ior tables", "in"),
    ("render: the plugin's 100 KB material name is cut (new)", ["render", "{longmat}", "-o", "{tmp}/lm.exr"], 2,
     "characters]...AAAAAAAAAAAAAAAAAAAAAAAA' is not one of", "in"),
    # --- issue 24: no output is an input of the same run ---
    ("invert --maps -o DIR beside the scene's alpha.exr (was overwritten)", ["invert", "--maps", "--scene",
     "{tmp}/invscene/scene.xml", "--reference", "{tmp}/invscene/ref.exr", "-o", "{tmp}/invscene"], 2,
     "alpha.exr' is the input", "in"),
    ("render -o the scene's own texture (new)", ["render", "{tmp}/invscene/scene.xml", "-o",
     "{tmp}/invscene/alpha.exr"], 2, "alpha.exr' is the input", "in"),
    ("fit: -o is the data file itself (new)", ["fit", "{tmp}/data_as.png", "-o", "{tmp}/data_as.png"], 2,
     "data_as.png' is the input", "in"),
    ("invert: the reference named like an output (new)", ["invert", "--reference", "{tmp}/inref/invert.png",
     "-o", "{tmp}/inref"], 2, "invert.png' is the input", "in"),
    # --- issue 24: one writer per output set ---
    ("render: another run is writing the same outputs (was a mixed set)", ["render", "{tiny}", "-o",
     "{tmp}/locked.exr"], 2, "is being written by another run (pid", "locked"),
    ("fit: another run is writing the same plot (new)", ["fit", "{csv}", "-o", "{tmp}/locked.png"], 2,
     "is being written by another run (pid", "locked"),
    # --- issue 24: memory and table dimensions checked before allocation, sensible units ---
    ("invert --maps --map-size 100000 (was 74.5 GiB allocated)", ["invert", "--maps", "--map-size", "100000",
     "-o", "{tmp}/mapsize"], 2, "of memory needed, but only", "in"),
    ("fit: a .pbsdf whose dimensions overflow (new)", ["fit", "{tmp}/overflow.pbsdf"], 2,
     "field 'M': dimensions", "in"),
    ("fit: a valid but huge .pbsdf (sparse 1.25 TiB)", ["fit", "{huge}"], 2,
     "TiB of memory needed, but only", "in"),
    # --- issue 24: options checked before the work, one line ---
    ("fit --seed -3 on a table (was a traceback)", ["fit", "{tmp}/small.pbsdf", "--seed", "-3"], 2,
     "--seed must be an integer in [0, 2^32), got -3", "in"),
    ("validate: another run is writing the same report folder (new)", ["validate", "-o", "{tmp}/lockedreport",
     "--quick"], 2, "is being written by another run (pid", "locked"),
    ("fit --seed 2^64 on a table (new)", ["fit", "{tmp}/small.pbsdf", "--seed", str(2**64)], 2,
     "--seed must be an integer in [0, 2^32)", "in"),
    # --- issue 24: the free space for the outputs checked before the work (the disk reads 50 KB free) ---
    ("render: no room for the EXR and PNGs (refused before the first pass, not after the render)",
     ["render", "{tiny}", "-o", "{tmp}/dfull.exr"], 2,
     "dfull.exr' (12x8 film): about 6.63 MiB needed, but", "diskfull"),
    ("render --no-png: no room for the EXR alone (the estimate counts only what is written)",
     ["render", "{tiny}", "-o", "{tmp}/dfull.exr", "--no-png"], 2,
     "dfull.exr' (12x8 film): about 69.6 KiB needed, but", "diskfull"),
    ("demo: no room for the pictures (refused before the first pass)",
     ["demo", "-o", "{tmp}/dfull", "--width", "16", "--height", "10", "--spp", "1"], 2,
     "dfull' (16x10 film): about 10.4 MiB needed, but", "diskfull"),
    ("fit: no room for the plot and its _models plot (refused before the data file is read)", ["fit", "{csv}", "-o", "{tmp}/dfull.png"],
     2, "dfull.png' and 1 more: about 128 MiB needed, but", "diskfull"),
    ("export: no room for the table (refused before the tabulation)", ["export", "{tmp}/dfull.pbsdf", "--rms-slope",
     "0.3", "--n", "1.5"], 2, "dfull.pbsdf' (resolution 37x55x55): about", "diskfull"),
    ("invert: no room for the history and the plot (refused before the inversion)",
     ["invert", "-o", "{tmp}/dfull_inv"], 2, "invert_history.csv' and 1 more: about 64", "diskfull"),
    ("invert --maps: no room for the maps (refused before the inversion)",
     ["invert", "--maps", "--map-size", "8", "-o", "{tmp}/dfull_maps"], 2,
     "invert_maps_history.csv' and 7 more: about 64", "diskfull"),
    ("invert --maps --scene: no room for maps of the scene's texture size (refused before the inversion)",
     ["invert", "--maps", "--scene", "{tmp}/invscene16/scene.xml", "--reference", "{tmp}/invscene16/ref.exr", "-o",
      "{tmp}/dfull_scene"], 2, "dfull_scene' (6x6 maps): about 64", "diskfull"),
    # --- issue 33: no output replaces an input (each option that names a file: tests/test_cli_inputs.py) ---
    ("stokes: a chart named like a frame (new)", ["stokes", "--frames", "{in33}/s_dolp.png", "{in33}/f1.png",
     "{in33}/f2.png", "--angles", "0,45,90", "-o", "{in33}/s.exr"], 2, "s_dolp.png' is the input", "in"),
    ("fit --json the data file itself (new)", ["fit", "{in33}/twelve.csv", "--json", "{in33}/twelve.csv", "-q"], 2,
     "twelve.csv' is the input", "in"),
    ("export: the table is the --fit result it reads (new)", ["export", "{in33}/fit.pbsdf", "--fit",
     "{in33}/fit.pbsdf"], 2, "fit.pbsdf' is the input", "in"),
    # --- issue 33: no silent empty or degenerate answer ---
    ("fit: 2 geometries for 3 parameters (was 'adequate')", ["fit", "{in33}/two.csv", "-q"], 0,
     "warning: 2 distinct geometries cannot determine the 3 fitted parameter(s)", "in"),
    ("stokes: every pixel below the black level (new)", ["stokes", "--mosaic", "{in33}/dark.npy", "--black-level",
     "64", "--read-noise", "2", "-o", "{tmp}/dark.exr"], 2,
     "dark.npy: every pixel is below the black level 64 DN beyond the read noise (the brightest is 3 DN)", "in"),
    ("invert --mask of zeros (new)", ["invert", "--maps", "--scene", "{tmp}/invscene16/scene.xml", "--reference",
     "{tmp}/invscene16/ref.exr", "--mask", "{in33}/zeros16.npy", "-o", "{tmp}/zeromask"], 2,
     "zeros16.npy' leaves out every pixel: nothing to fit", "in"),
    ("stokes --mosaic of zeros: no light reached the sensor (was an all-zero EXR, exit 0) (new)", ["stokes",
     "--mosaic", "{in33}/zeros16.npy", "-o", "{tmp}/nolight.exr"], 2, "zeros16.npy: no pixel is above the black level "
     "0 DN beyond the read noise (the brightest is 0 DN): no light reached the sensor", "in"),
    ("stokes --frames all at the black level (new)", ["stokes", "--frames", "{in33}/blk0.png", "{in33}/blk1.png",
     "{in33}/blk2.png", "--angles", "0,60,120", "--black-level", "2", "-o", "{tmp}/nolight.exr"], 2,
     "the frames: no pixel is above the black level 2 DN beyond the read noise (the brightest is 2 DN)", "in"),
    ("invert: a black reference, S0 = 0 everywhere (new)", ["invert", "--reference", "{in33}/black.exr", "--res",
     "16", "-o", "{tmp}/black"], 2, "black.exr' has peak |S0| = 0, outside the accepted range [1e-10, 1e+10]", "in"),
    ("invert --fit '' (was: the defaults fitted)", ["invert", "--fit", "", "-o", "{tmp}/fitempty"], 2,
     "--fit must list parameters from rms_slope, eta, k, got ''", "in"),
    ("invert --maps --fit '' (was: the preset's fitted)", ["invert", "--maps", "--fit", "", "-o", "{tmp}/fitempty"], 2,
     "--fit must list parameters from alpha, rms_slope, eta, k, specular_reflectance, got ''", "in"),
    # --- issue 33: sizes known before memory is taken; no library exception reaches the user ---
    ("stokes --analysis whose .npy header lies (new)", ["stokes", "--mosaic", "{in33}/mosaic.npy", "--analysis",
     "{in33}/lie.npy", "-o", "{tmp}/lie.exr"], 2,
     "lie.npy': its header says 100000x100000x4x4 float64 values (1.16 TiB), but the file holds 8 B", "in"),
    ("stokes: a truncated PNG frame (new)", ["stokes", "--frames", "{in33}/trunc.png", "{in33}/f1.png",
     "{in33}/f2.png", "--angles", "0,45,90", "-o", "{tmp}/trunc.exr"], 2,
     "trunc.png': cannot read it as an image (image file is truncated)", "in"),
    ("stokes: three 9600x9600 frames, 2 GiB available (was an allocation error after 20 s)", ["stokes", "--frames",
     "{in33}/big.png", "{in33}/big.png", "{in33}/big.png", "--angles", "0,45,90", "-o", "{tmp}/big.exr"], 2,
     "the Stokes images of 3 frame(s), 276480000 raw values (128 B each): about 33 GiB of memory needed", "lowmem"),
    ("render: a texture whose PNG header claims 100000x100000 (new)", ["render", "{in33}/hugetex.xml", "-o",
     "{tmp}/hugetex.exr"], 2, "hugetex.png' (100000x100000x1): about 37.3 GiB of memory needed", "lowmem"),
    ("invert --tiles 1000x1000 on a 6x6 map: refused before any scene loads (was after)", ["invert", "--maps",
     "--scene", "{tmp}/invscene16/scene.xml", "--camera", "{in33}/cam.json", "--light", "{in33}/cam.json",
     "--reference", "{tmp}/invscene16/ref.exr", "--tiles", "1000x1000", "-o", "{tmp}/tiles"], 2,
     "--tiles must be 1..6 x 1..6 for a 6 x 6-texel map, got 1000 x 1000 (the scene's largest texture, "
     "'alpha.exr', read before any scene loads)", "noscene"),
    ("invert --tiles 1000x1000, the map a Radiance .hdr texture: its header read too (new)", ["invert", "--maps",
     "--scene", "{in33}/hdrtex.xml", "--camera", "{in33}/cam.json", "--light", "{in33}/cam.json", "--reference",
     "{tmp}/invscene16/ref.exr", "--tiles", "1000x1000", "-o", "{tmp}/tiles"], 2,
     "--tiles must be 1..6 x 1..6 for a 6 x 6-texel map, got 1000 x 1000 (the scene's largest texture, 'alpha.hdr'",
     "noscene"),
    ("invert --tiles 1000x1000, the map's texture header unreadable: refused naming it (new)", ["invert", "--maps",
     "--scene", "{in33}/badhdrtex.xml", "--camera", "{in33}/cam.json", "--light", "{in33}/cam.json", "--reference",
     "{tmp}/invscene16/ref.exr", "--tiles", "1000x1000", "-o", "{tmp}/tiles"], 2,
     "bad.hdr': not a readable Radiance RGBE file (its header)", "noscene"),
    ("invert --tiles 20x20, alpha a constant (no texture file to read) (new)", ["invert", "--maps", "--scene",
     "{in33}/constalpha.xml", "--camera", "{in33}/cam.json", "--light", "{in33}/cam.json", "--reference",
     "{tmp}/invscene16/ref.exr", "--tiles", "20x20", "-o", "{tmp}/tiles"], 2,
     "--tiles 20x20 makes 400 tiles, more than the 256 pixels of the 1 --reference picture(s)", "noscene"),
    # CSV and .npz inputs sized before they are decoded (a CSV's values bounded by its size)
    ("fit: a CSV of 50000 rows with 8 MiB available: its values counted before it is decoded (new)", ["fit",
     "{in33}/dense.csv", "-q"], 2, "dense.csv' (391 KiB: at most 200005 values, 64 B each to parse): about 12.2 MiB "
     "of memory needed, but only 8 MiB is available; split it into smaller files", "mem8m"),
    ("accuracy --atlas: a .npz whose member's header claims 1.16 TiB (new)", ["accuracy", "--theta-i", "30",
     "--rms-slope", "0.3", "--atlas", "{in33}/lie.npz"], 2, "lie.npz', array 'a.npy': its header says "
     "100000x100000x4x4 float64 values (1.16 TiB), but the file holds 8 B (truncated or damaged)", "in"),
    ("accuracy --atlas: a .npz of pickled Python objects (new)", ["accuracy", "--theta-i", "30", "--rms-slope", "0.3",
     "--atlas", "{in33}/objects.npz"], 2, "objects.npz', array 'a.npy' holds Python objects, not numbers", "in"),
    ("accuracy --atlas: another .npz, not an atlas (was KeyError, 'unexpected') (new)", ["accuracy", "--theta-i",
     "30", "--rms-slope", "0.3", "--atlas", "{in33}/other.npz"], 2,
     "other.npz' has no array 'provenance': not an accuracy atlas", "in"),
    ("accuracy --atlas: a zip without arrays (new)", ["accuracy", "--theta-i", "30", "--rms-slope", "0.3",
     "--atlas", "{in33}/plain.zip"], 2, "plain.zip' holds no .npy array: not a .npz file", "in"),
    ("accuracy --atlas: a text file named .npz (new)", ["accuracy", "--theta-i", "30", "--rms-slope", "0.3",
     "--atlas", "{in33}/text.npz"], 2, "text.npz': not a readable .npz file (File is not a zip file)", "in"),
    # --- issue 33: every wait bounded, the limit named (HYDE_BSDF_CONNECT_TIMEOUT is 0.5 s in these rows;
    # the server that accepts and never answers, the issue's case, is in tests/test_waits.py)
    ("invert --scheduler: a port whose accept queue is full (the TCP handshake never completes) (new)",
     ["invert", "--maps", "--scene", "{tmp}/invscene16/scene.xml", "--camera", "{in33}/cam.json", "--light",
      "{in33}/cam.json", "--reference", "{tmp}/invscene16/ref.exr", "--tiles", "2", "--scheduler", "{server}", "-o",
      "{tmp}/sched"], 2, "no dask scheduler answers there (no answer within 0.5 s (HYDE_BSDF_CONNECT_TIMEOUT): "
     "Timed out trying to connect to", "server-full"),
    ("invert --scheduler: a server that starts a dask message and stalls (new)", ["invert", "--maps", "--scene",
     "{tmp}/invscene16/scene.xml", "--camera", "{in33}/cam.json", "--light", "{in33}/cam.json", "--reference",
     "{tmp}/invscene16/ref.exr", "--tiles", "2", "--scheduler", "{server}", "-o", "{tmp}/sched"], 2,
     "no dask scheduler answers there (no answer within 0.5 s (HYDE_BSDF_CONNECT_TIMEOUT))", "server-stall"),
    ("invert --tiles --workers 2 whose tiles outlast HYDE_BSDF_TASK_TIMEOUT=0.01 s: one line, not 'unexpected' (new)",
     ["invert", "--maps", "--scene", "{cap}/sample.xml", "--camera", "{cap}/camera.json", "--light",
      "{cap}/lights.json", "--reference", "{cap}/ref.exr", "--tiles", "2", "--workers", "2", "-o", "{tmp}/tasklimit"],
     2, " s (HYDE_BSDF_TASK_TIMEOUT=0.01 s); 0 of 4 tiles had finished", "tasklimit"),
    ("invert --scheduler: a server that answers noise, not dask's protocol (refused at once) (new)", ["invert",
     "--maps", "--scene", "{tmp}/invscene16/scene.xml", "--camera", "{in33}/cam.json", "--light", "{in33}/cam.json",
     "--reference", "{tmp}/invscene16/ref.exr", "--tiles", "2", "--scheduler", "{server}", "-o", "{tmp}/sched"], 2,
     "no dask scheduler answers there (its answer is not dask's protocol: ", "server-noise"),
    # --- issue 33: a signal is one line whatever it is and wherever it lands
    ("render: SIGHUP (the terminal closed) removes the temporaries (new)", ["render", "{tiny}", "-o",
     "{tmp}/sighup.exr", "--spp", "200000", "--chunks", "20000"], 129, "hyde-bsdf render: terminated (SIGHUP)",
     "sighup"),
    ("render: Ctrl-C to the whole process group, as a terminal sends it (new)", ["render", "{tiny}", "-o",
     "{tmp}/sigint-group.exr", "--spp", "200000", "--chunks", "20000"], 130, "hyde-bsdf render: interrupted",
     "sigint-group"),
    # --- issue 33: control characters in an output name never reach the terminal or the XML ---
    ("render -o with an ESC in the name (new)", ["render", "{tiny}", "-o", "{tmp}/a\x1b[31mred.exr"], 2,
     "the name holds control characters (\\x1b); give a name without them", "in"),
    ("fit -o with a newline in the name (new)", ["fit", "{csv}", "-o", "{tmp}/plot\nname.png"], 2,
     "the name holds control characters (\\n)", "in"),
]


def _scatter_on_a_dead_cluster(p):
    """mom.scatter over a dask cluster whose only worker died (issue 15: it waited forever); the
    grace period for a cluster without workers is shortened from 60 s to 0.5 s here."""
    distributed = pytest.importorskip("distributed")
    from hyde_bsdf import mom
    from hyde_bsdf.mom import gather

    saved = gather.NO_WORKER_GRACE_S, gather.POLL_S
    gather.NO_WORKER_GRACE_S, gather.POLL_S = 0.5, 0.05
    try:
        with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1,
                                      dashboard_address=None) as cluster, distributed.Client(cluster) as client:
            client.sync(cluster.workers[0].close)
            mom.scatter(20.0, 2, 0.0, 1.0, 0.0, 0.0, pts_per_wl=6, executor=client.get_executor(), progress=False)
    finally:
        gather.NO_WORKER_GRACE_S, gather.POLL_S = saved


def _scatter_on(executor):
    from hyde_bsdf import mom
    mom.scatter(20.0, 2, 0.0, 1.0, 0.0, 0.0, pts_per_wl=6, executor=executor, progress=False)


def _scatter_on_a_raw_client(p):
    """A dask Client where an executor is expected: refused before any work (no cluster needed:
    the check looks at the type, a stand-in with dask's module and class name)."""
    client = type("Client", (), {"__module__": "distributed.client"})()
    _scatter_on(client)


def _scatter_too_long(p):
    """2e6 wavelengths at 40 points each: the surface alone needs 4.77 GiB; refused before it is drawn."""
    from unittest import mock

    from hyde_bsdf import mom
    with mock.patch("hyde_bsdf.resources.available_memory", lambda: 2**30):
        mom.scatter(2e6, 2000, 0.0, 1.0, 0.0, 0.0, pts_per_wl=40, progress=False)


def _export_while_locked(p):
    from hyde_bsdf.fit.pbsdf_export import export_pbsdf
    from hyde_bsdf.resources import OutputLock

    with OutputLock([p["tmp"] / "locked.pbsdf"]):
        export_pbsdf(p["tmp"] / "locked.pbsdf", rms_slope=0.3, n=1.5, resolution=(4, 4, 4), progress=False)


def _a_task_that_never_ends(p):
    """The package's own process pool (mom.solver.process_pool) whose one task sleeps for an hour: the
    limit (timeout=0.3 s) ends the wait, and end_pool kills the worker rather than wait for the task (the
    shutdown, and the interpreter's exit after it, waited for the task: a wait without an end)."""
    import time

    from hyde_bsdf.mom.gather import end_pool, gather
    from hyde_bsdf.mom.solver import process_pool

    ex = process_pool(1)
    try:
        gather(ex, time.sleep, [3600], timeout=0.3)
    finally:
        workers = list(ex._processes.values())
        end_pool(ex, finished=False)
        assert [w.exitcode for w in workers] == [-signal.SIGKILL], [w.exitcode for w in workers]


def _scatter_past_its_limit(p):
    """mom.scatter on its own pool with timeout=0.001 s: no partition finishes in time; the pool's workers
    are ended, none is left running."""
    import multiprocessing

    from hyde_bsdf import mom
    try:
        mom.scatter(20.0, 2, 0.0, 1.0, 0.0, 0.0, pts_per_wl=6, timeout=0.001, progress=False)
    finally:
        assert not multiprocessing.active_children()


def _api_rows():
    from hyde_bsdf.mom import ExecutorError
    from hyde_bsdf.render.renderer import load_scene, plan_passes, prepare_variant, render_stokes
    from hyde_bsdf.io.stokes_exr import write_stokes_exr

    def loaded(path):            # a scene loaded by Mitsuba itself, without our XML checks
        import mitsuba as mi

        prepare_variant("llvm_ad_spectral_polarized")
        return mi.load_file(str(path))

    return [
        ("render_stokes of a loaded scene without a sensor", lambda p: render_stokes(loaded(p["nosensor"])),
         UsageError, "the scene has no sensor"),
        ("render_stokes of a loaded ptracer scene", lambda p: render_stokes(loaded(p["ptracer"])), UsageError,
         r"integrator \(AdjointIntegrator\) is not a sampling integrator"),
        ("render_stokes spp=0", lambda p: render_stokes(p["tiny"], spp=0), UsageError, "spp must be an integer >= 1"),
        ("render_stokes seed=-1", lambda p: render_stokes(p["tiny"], seed=-1), UsageError,
         r"seed must be an integer in \[0, 32767\]"),
        ("render_stokes of a number", lambda p: render_stokes(3), UsageError, "scene_or_path must be"),
        ("load_scene without a sensor", lambda p: (prepare_variant("scalar_rgb"), load_scene(p["nosensor"])),
         UsageError, "has no <sensor>"),
        ("write_stokes_exr to .png", lambda p: write_stokes_exr(p["tmp"] / "x.png", {}), ValueError,
         r"must end in \.exr"),
        ("plan_passes beyond 2^16 passes", lambda p: plan_passes(1000, 1000, 10**7), UsageError,
         "at most 65536 passes"),
        ("mom.scatter given a raw dask Client, not its executor (was a traceback)", _scatter_on_a_raw_client,
         UsageError, r"^executor is a dask Client; pass client.get_executor\(\)"),
        ("mom.scatter given something that is not an executor (new)", lambda p: _scatter_on("a pool"),
         UsageError, r"^executor must be a concurrent.futures.Executor \(or None\), got str$"),
        ("mom.scatter whose surface alone exceeds the memory (was allocated; 1 GiB available here)",
         _scatter_too_long, UsageError, r"^the MoM surface \(80000000 points, 64 B each\): about 4\.77 GiB of "
         r"memory needed, but only 819 MiB is available \(80% of the 1 GiB available\); use a shorter length_wl"),
        ("export_pbsdf while another run writes the same file (new)", _export_while_locked, UsageError,
         r"locked.pbsdf' is being written by another run \(pid \d+\)"),
        ("a process pool whose task never ends: the limit, then its worker killed (was: the shutdown waited)",
         _a_task_that_never_ends, ExecutorError, r"^hyde-bsdf: the process pool of 1 workers finished no task for \d+ s "
                                                 r"\(timeout=0\.3 s\); 0 of 1 tasks had finished$"),
        ("mom.scatter past its timeout: one line, no worker left (new)", _scatter_past_its_limit, ExecutorError,
         r"^mom\.scatter: the process pool of \d+ workers finished no partition for \d+ s \(timeout=0\.001 s\); 0 of 2 "
         r"partitions had finished$"),
        ("mom.scatter on a dask cluster whose only worker died (was a hang)", _scatter_on_a_dead_cluster,
         ExecutorError, r"^mom\.scatter: the dask cluster at inproc://\S+ is dead: it has no worker .*; 0 of 2 "
                        r"partitions had finished$"),
    ]


def _stokes_exr(path, size, value):
    """A Stokes EXR (R, G, B, S0.R ... S3.B) of size x size pixels: S0 = value, S1 = value / 2, S2 = S3 = 0."""
    import numpy as np
    import OpenEXR

    names = ["R", "G", "B"] + [f"S{i}.{c}" for i in range(4) for c in "RGB"]
    level = {"R": 1.0, "G": 1.0, "B": 1.0, "S0": 1.0, "S1": 0.5, "S2": 0.0, "S3": 0.0}
    ch = {n: np.full((size, size), value * level[n.split(".")[0]], np.float32) for n in names}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, ch).write(str(path))


def _plugin_scenes(tmp):
    """Scenes whose hyde parameters are textures or values Mitsuba evaluates (issue 15 rows)."""
    import numpy as np
    import OpenEXR
    from PIL import Image

    eta = np.full((2, 2), 1.5, np.float32)
    eta[1, 0] = -1.5
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"Y": eta}).write(str(tmp / "negeta.exr"))
    Image.fromarray(np.array([[30, 83], [200, 255]], np.uint8), mode="L").save(tmp / "rough8.png")

    def scene(name, bsdf):
        (tmp / f"{name}.xml").write_text(SCENE.replace('<bsdf type="diffuse"/>', bsdf))
        return tmp / f"{name}.xml"

    return {
        "negeta": scene("negeta", f'<bsdf type="hyde"><texture type="bitmap" name="eta"><string name="filename" '
                                  f'value="{tmp / "negeta.exr"}"/></texture><float name="k" value="0"/></bsdf>'),
        "hugeeta": scene("hugeeta", '<bsdf type="hyde"><float name="eta" value="1e10"/><float name="k" value="0"/></bsdf>'),
        "png8": scene("png8", f'<bsdf type="hyde"><texture type="bitmap" name="alpha"><string name="filename" '
                              f'value="{tmp / "rough8.png"}"/></texture><string name="material" value="Au"/></bsdf>'),
        "alpha0": scene("alpha0", '<bsdf type="hyde"><float name="alpha" value="0"/></bsdf>'),
    }


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bad")
    (tmp / "file.txt").write_text("a regular file\n")
    (tmp / "tiny.xml").write_text(SCENE)
    (tmp / "nosensor.xml").write_text('<scene version="3.0.0"><shape type="sphere"/><emitter type="constant"/>'
                                      "</scene>")
    (tmp / "ptracer.xml").write_text(SCENE.replace('<integrator type="path">', '<integrator type="ptracer">'))
    (tmp / "badhyde.xml").write_text(SCENE.replace('<bsdf type="diffuse"/>', '<bsdf type="hyde"><float name="rms_slope" value="-1"/></bsdf>'))
    _stokes_exr(tmp / "ref1e30.exr", 16, 1e30)
    (tmp / "kept").mkdir()
    (tmp / "kept" / "invert_history.csv").write_text("a previous run's output\n")
    (tmp / "dir.exr").mkdir()
    (tmp / "pngdir_dolp.png").mkdir()
    (tmp / "notreport").mkdir()
    (tmp / "notreport" / "thesis.tex").write_text("a user's file")
    (tmp / "site").mkdir()                                  # a web site: its index.html is not a report
    (tmp / "site" / "index.html").write_text("<html>my site</html>")
    (tmp / "site" / "style.css").write_text("body {}")
    (tmp / "full").mkdir()                                  # an earlier render's output set
    for name in ("a.exr", "a_intensity.png", "a_dolp.png", "a_aolp.png", "a_docp.png", "a_rgb.png", "plot.png"):
        (tmp / "full" / name).write_text(f"old {name}")
    (tmp / "stale").mkdir()
    import numpy as np

    from hyde_bsdf.io.measurements import write_measurements
    from hyde_bsdf.fit.mueller_fit import synthetic_measurements

    th = np.radians([20.0, 40.0, 60.0])
    meas = synthetic_measurements(th, th, np.full(3, np.pi), n=1.5, k=3.0, rms_slope=0.3, rng=3)
    write_measurements(tmp / "meas.csv", meas)
    text = (tmp / "meas.csv").read_text().splitlines()
    head = [ln for ln in text if ln.startswith("theta")][0]
    rows = [ln for ln in text if ln[:1].isdigit()]
    (tmp / "copies.csv").write_text("\n".join([head] + rows * 1000) + "\n")
    cells = rows[1].split(",")
    cells[head.split(",").index("M22")] = "-1.3"
    (tmp / "impossible.csv").write_text("\n".join([head, rows[0], ",".join(cells), rows[2]]) + "\n")
    bad = rows[1].split(",")
    bad[head.split(",").index("M01")] = "x"
    (tmp / "crlines.csv").write_bytes(("# measured on a classic Mac\r" + "\r".join([head, rows[0], ",".join(bad)])
                                       + "\r").encode())
    return {"site": tmp / "site", "full": tmp / "full", "stale": tmp / "stale",
            "copies": tmp / "copies.csv", "impossible": tmp / "impossible.csv", "crcsv": tmp / "crlines.csv",
            "tmp": tmp, "file": tmp / "file.txt", "tiny": tmp / "tiny.xml", "nosensor": tmp / "nosensor.xml",
            "ptracer": tmp / "ptracer.xml", "inverse": ROOT / "hyde_bsdf" / "data" / "scenes" / "inverse.xml", "csv": tmp / "meas.csv",
            "notreport": tmp / "notreport", "badhyde": tmp / "badhyde.xml", "ref1e30": tmp / "ref1e30.exr",
            **_plugin_scenes(tmp), **_gate_files(tmp)}


def _table_layout(m_shape):
    import numpy as np

    layout = {n: (np.dtype(np.float32), (1, 3)) for n in ("theta_h", "theta_d", "phi_d")}
    layout["wvls"] = (np.dtype(np.uint16), (5,))
    layout["M"] = (np.dtype(np.float32), m_shape)
    return layout


def _tables(tmp):
    """small.pbsdf (a real 4x4x4 export); overflow.pbsdf: M's dimensions multiply past 2^64."""
    from hyde_bsdf.fit.pbsdf_export import export_pbsdf
    from hyde_bsdf.io.pbsdf_file import _header

    export_pbsdf(tmp / "small.pbsdf", rms_slope=0.3, n=1.5, resolution=(4, 4, 4), progress=False)
    head, offsets, _ = _header(_table_layout((2**40, 2**40, 2**40, 5, 4, 4)))
    (tmp / "overflow.pbsdf").write_bytes(head.ljust(offsets["M"], b"\0"))


def _huge_table(folder):
    """A valid 4096x1024x1024 table, 1.25 TiB, as a sparse file (no disk used), outside the
    snapshot folder (the snapshot reads every file)."""
    from hyde_bsdf.io.pbsdf_file import _header

    folder.mkdir(exist_ok=True)
    head, _, total = _header(_table_layout((4096, 1024, 1024, 5, 4, 4)))
    with open(folder / "huge.pbsdf", "wb") as fh:
        fh.write(head)
        fh.truncate(total)
    return folder / "huge.pbsdf"


def _gate_files(tmp):
    """Special files, huge cells and hostile names for the issue 24 rows."""
    import socket

    for name in ("out_fifo.exr", "pipe.csv", "plot_fifo.png", "b_dolp.png", "tex_fifo.png", "scene_fifo.xml"):
        os.mkfifo(tmp / name)
    for name in ("sock.exr", "sock.csv"):
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(tmp / name))
        s.close()                              # the socket file stays
    os.symlink("/proc/self/fd/1", tmp / "link_fd.exr")
    (tmp / "sub").mkdir()
    os.symlink("../file.txt", tmp / "sub" / "link_up.exr")
    head = "theta_i_deg,theta_r_deg,phi_deg,M01"
    (tmp / "bigcell.csv").write_text(f"{head}\n20,20,180,0.1\n30,30,180,{'x' * 200_000}\n")
    (tmp / "bighead.csv").write_text(f"{head},{'M' * 200_000}\n20,20,180,0.1,0\n")

    def scene(name, bsdf):
        (tmp / f"{name}.xml").write_text(SCENE.replace('<bsdf type="diffuse"/>', bsdf))
        return tmp / f"{name}.xml"

    bitmap = '<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="{}"/>' \
             '</texture></bsdf>'
    _tables(tmp)
    inv = tmp / "invscene"                        # a user's scene folder: scene.xml, its alpha.exr, a reference
    inv.mkdir()
    _stokes_exr(inv / "alpha.exr", 4, 0.3)
    _stokes_exr(inv / "ref.exr", 16, 1.0)
    (inv / "scene.xml").write_text(SCENE.replace('<bsdf type="diffuse"/>', '<bsdf type="hyde"><texture '
                                   'type="bitmap" name="alpha"><string name="filename" value="alpha.exr"/></texture></bsdf>'))
    big = tmp / "invscene16"                      # the same at 16x16 px with a 6x6 alpha map and its reference
    big.mkdir()
    import numpy as np
    import OpenEXR
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"Y": np.full((6, 6), 0.3, np.float32)}).write(str(big / "alpha.exr"))
    _stokes_exr(big / "ref.exr", 16, 1.0)
    (big / "scene.xml").write_text((inv / "scene.xml").read_text().replace('"res" value="12"', '"res" value="16"')
                                   .replace('"height" value="8"', '"height" value="16"'))
    (tmp / "data_as.png").write_bytes((tmp / "meas.csv").read_bytes())   # a CSV under a plot's name
    (tmp / "inref").mkdir()
    _stokes_exr(tmp / "inref" / "invert.png", 16, 1.0)
    sys.path.insert(0, str(Path(__file__).parent))
    from test_signals import _inputs              # a calibrated capture: sample, camera, light, reference
    (tmp / "cap").mkdir()
    _inputs(tmp / "cap")
    return {"in33": _issue33_files(tmp), "cap": tmp / "cap",
            "fifotex": scene("fifotex", bitmap.format("tex_fifo.png")),
            "huge": _huge_table(tmp.parent / f"{tmp.name}_sparse"),
            "devtex": scene("devtex", bitmap.format("/dev/zero")),
            "dotdotmat": scene("dotdotmat", '<bsdf type="hyde"><string name="material" value="../ior/Au"/></bsdf>'),
            "longmat": scene("longmat", f'<bsdf type="hyde"><string name="material" value="{"A" * 100_000}"/></bsdf>')}


def _issue33_files(tmp):
    """Frames, CSVs, arrays and images for the issue 33 rows, in tmp/in33."""
    import io
    import json
    import struct
    import zipfile
    import zlib

    import numpy as np
    from PIL import Image

    from hyde_bsdf.fit.mueller_fit import synthetic_measurements
    from hyde_bsdf.io.measurements import write_measurements

    d = tmp / "in33"
    d.mkdir()
    for i, name in enumerate(("s_dolp.png", "f1.png", "f2.png")):
        Image.fromarray(np.full((8, 8), 100 + i, np.uint8)).save(d / name)
    for name, deg in (("two.csv", [20.0, 40.0]), ("twelve.csv", np.linspace(10.0, 70.0, 12))):
        th = np.radians(deg)
        write_measurements(d / name, synthetic_measurements(th, th, np.full(th.size, np.pi), n=1.5, k=3.0,
                                                            rms_slope=0.3, rng=33))
    for i in range(3):                             # frames at the black level 2 DN: no light
        Image.fromarray(np.full((8, 8), 2, np.uint8)).save(d / f"blk{i}.png")
    _stokes_exr(d / "black.exr", 16, 0.0)
    (d / "dense.csv").write_text("theta_i_deg,theta_r_deg,phi_deg,M01\n" + "1,1,1,0\n" * 50_000)
    (d / "fit.pbsdf").write_text(json.dumps({"note": "a fit result under a table's name"}))
    (d / "cam.json").write_text(json.dumps({"width": 16, "height": 16}))     # read after the --tiles check
    np.save(d / "dark.npy", np.full((8, 8), 3, np.uint16))
    np.save(d / "mosaic.npy", np.full((8, 8), 500, np.uint16))
    np.save(d / "zeros16.npy", np.zeros((16, 16)))
    with open(d / "lie.npy", "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False,
                                                  "shape": (100000, 100000, 4, 4)})
        fh.write(b"\0" * 8)

    def png(path, width, height, data):           # a grey PNG whose header claims width x height
        chunk = lambda kind, body: (struct.pack(">I", len(body)) + kind + body
                                    + struct.pack(">I", zlib.crc32(kind + body)))
        path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
                         + chunk(b"IDAT", data))

    scene16 = (tmp / "invscene16" / "scene.xml").read_text()
    (d / "hdrtex.xml").write_text(scene16.replace("alpha.exr", "alpha.hdr"))       # a Radiance RGBE texture
    (d / "alpha.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 6 +X 6\n" + bytes(6 * 6 * 4))
    (d / "badhdrtex.xml").write_text(scene16.replace("alpha.exr", "bad.hdr"))      # one whose header is garbage
    (d / "bad.hdr").write_bytes(b"\x00garbage")
    (d / "constalpha.xml").write_text(scene16.replace('<texture type="bitmap" name="alpha"><string name="filename" '
                                                      'value="alpha.exr"/></texture>', '<float name="alpha" value="0.3"/>'))
    with zipfile.ZipFile(d / "lie.npz", "w") as zf:           # a member whose header claims 1.16 TiB in 8 bytes
        head = io.BytesIO()
        np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False,
                                                    "shape": (100000, 100000, 4, 4)})
        zf.writestr("a.npy", head.getvalue() + b"\0" * 8)
    np.savez(d / "objects.npz", a=np.array([{"x": 1}], dtype=object))
    (d / "text.npz").write_text("not a zip\n")
    np.savez(d / "other.npz", x=np.arange(3))
    with zipfile.ZipFile(d / "plain.zip", "w") as zf:
        zf.writestr("readme.txt", "no arrays here")
    png(d / "trunc.png", 64, 64, zlib.compress(b"\0" * 10)[:5])
    png(d / "big.png", 9600, 9600, zlib.compress(b"\0" * 64))
    png(d / "hugetex.png", 100000, 100000, zlib.compress(b"\0" * 64))
    (d / "hugetex.xml").write_text(SCENE.replace('<bsdf type="diffuse"/>', '<bsdf type="diffuse"><texture type="bitmap" '
                                   'name="reflectance"><string name="filename" value="hugetex.png"/></texture></bsdf>'))
    return d


class _HostileServer:
    """A TCP port on 127.0.0.1 that is no dask scheduler (the ``server-MODE`` rows): ``full``, its accept
    queue full and never served, so a new connection's handshake never completes; ``stall``, the first 8 bytes of a dask message (one frame follows) and
    then nothing; ``noise``, 64 bytes that are not dask's protocol."""

    def __init__(self, mode):
        import socket
        import struct

        self.sock, self.conns = socket.socket(), []
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(0)
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        if mode == "full":                         # Linux queues backlog + 1 connections, then drops SYNs
            for _ in range(3):
                c = socket.socket()
                c.setblocking(False)
                with contextlib.suppress(BlockingIOError):
                    c.connect(self.sock.getsockname())
                self.conns.append(c)
            return
        answer = {"stall": struct.pack("<Q", 1), "noise": bytes(range(100, 164))}[mode]
        threading.Thread(target=self._serve, args=(answer,), daemon=True).start()

    def _serve(self, answer):
        while True:
            try:
                conn = self.sock.accept()[0]
                self.conns.append(conn)
                conn.sendall(answer)
            except OSError:
                return

    def close(self):
        for c in self.conns + [self.sock]:
            c.close()


def _snapshot(folder):
    """{relative path: (bytes, mode)} of every regular file under ``folder`` except our own
    temporaries, (kind, inode) of every FIFO, socket or device, and ("link", target) of every
    symlink: "nothing changed or lost" covers contents, modes and special files alike."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if any(TEMP_NAME_RE.match(part) for part in rel.parts):
            continue
        st = os.lstat(p)
        if stat.S_ISREG(st.st_mode):
            out[str(rel)] = (p.read_bytes(), stat.S_IMODE(st.st_mode))
        elif stat.S_ISLNK(st.st_mode):
            out[str(rel)] = ("link", os.readlink(p))
        elif stat.S_ISDIR(st.st_mode):
            out[str(rel)] = ("dir",)              # an empty folder tree counts too
        else:
            out[str(rel)] = (stat.S_IFMT(st.st_mode), st.st_ino)
    return out


def _fill(argv, paths):
    return [a.format(**{k: str(v) for k, v in paths.items()}) for a in argv]


def _subprocess(argv, how, timeout=None):
    timeout = scaled(120) if timeout is None else timeout
    cmd = [sys.executable, "-m", "hyde_bsdf.app.cli", *argv]
    if how == "pipe":
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        proc.stdout.close()                       # the reader went away before any output
        err = proc.stderr.read()
        return proc.wait(timeout=timeout), "", err
    if how in ("sigint", "sigterm", "sighup", "sigint-group"):
        group = how == "sigint-group"             # Ctrl-C in a terminal reaches the whole process group
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=group)
        watchdog = threading.Timer(timeout, proc.kill)
        watchdog.start()
        err = ""
        try:
            while "spp (" not in err:             # the first progress line: rendering has begun
                line = proc.stderr.readline()     # whole lines: what the reader buffers past them is lost
                if not line:
                    break
                err += line
            sig = {"sigint": signal.SIGINT, "sighup": signal.SIGHUP}.get(how, signal.SIGTERM)
            os.killpg(proc.pid, signal.SIGINT) if group else proc.send_signal(sig)
            out, rest = proc.communicate(timeout=timeout)
        finally:
            watchdog.cancel()
        return proc.returncode, out, err + rest
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.parametrize("row", CLI_ROWS, ids=[r[0] for r in CLI_ROWS])
def test_cli_bad_input(row, paths, capsys, monkeypatch):
    name, argv, code, needle, how = row
    server = None
    if how.startswith("server-"):                 # a port that is no dask scheduler, the wait's limit 0.5 s
        pytest.importorskip("distributed")
        server = _HostileServer(how.split("-", 1)[1])
        paths = {**paths, "server": server.address}
        monkeypatch.setenv("HYDE_BSDF_CONNECT_TIMEOUT", "0.5")
    argv = _fill(argv, paths)
    if how == "cuda":
        import drjit as dr

        if dr.has_backend(dr.JitBackend.CUDA):
            pytest.skip("hardware-dependent: this machine has a CUDA GPU, so the variant works")
    before = _snapshot(paths["tmp"])
    if how == "stale":                            # what a SIGKILLed run (a dead pid) left behind
        from hyde_bsdf.io.atomic import _HOST

        stale = [paths["stale"] / f".a.exr.tmp-{_HOST}-4194999-abc123.exr",
                 paths["stale"] / f".report.tmp-{_HOST}-4194999-abc123"]
        stale[0].write_bytes(b"half")
        stale[1].mkdir()
    if how.startswith("enospc@"):                 # the n-th file's data cannot reach the disk
        nth, calls, real_fsync = int(how.split("@")[1]), [], os.fsync

        def fsync(fd):
            calls.append(fd)
            if len(calls) == nth:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return real_fsync(fd)

        monkeypatch.setattr(os, "fsync", fsync)
    lock = contextlib.nullcontext()
    if how == "locked":                           # another run holds the outputs (same pid here)
        from hyde_bsdf.resources import OutputLock
        lock = OutputLock([paths["tmp"] / "locked.exr", paths["tmp"] / "locked.png", paths["tmp"] / "lockedreport"])
    if how in ("sub", "sigint", "sigterm", "sighup", "sigint-group", "pipe"):
        got, out, err = _subprocess(argv, how)
    else:
        if how in ("lowmem", "mem8m"):
            avail = 2 * 2**30 if how == "lowmem" else 8 * 2**20
            monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: avail)
        if how == "diskfull":
            usage = shutil.disk_usage(paths["tmp"])
            monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=50_000))

            def no_pass(*args, **kwargs):
                raise AssertionError("a render pass ran before the free space was checked")
            monkeypatch.setattr("hyde_bsdf.render.renderer._render_pass", no_pass)
        if how == "tasklimit":                    # the pool's workers are killed at the limit (end_pool)
            monkeypatch.setenv("HYDE_BSDF_TASK_TIMEOUT", "0.01")
        if how == "noscene":                      # refused before any scene loads: a load fails the row
            def no_scene(*args, **kwargs):
                raise AssertionError("a scene was loaded before the refusal")
            monkeypatch.setattr("hyde_bsdf.render.camera.calibrated_scene", no_scene)
            monkeypatch.setattr("hyde_bsdf.render.renderer.load_scene_nearest", no_scene)
        if how == "noscripts":
            monkeypatch.setattr("hyde_bsdf.app.report.build.VALIDATION_DIR", paths["tmp"] / "no_validation")
        monkeypatch.chdir(paths["tmp"])
        try:
            with lock:
                got = cli.main(argv)
        except SystemExit as exc:                 # argparse errors of commands that do not catch them
            got = exc.code
        out, err = capsys.readouterr()
    if server is not None:
        server.close()
    assert got == code, (got, err[-2000:])
    assert "Traceback" not in err and "Traceback" not in out, err[-3000:]
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip()]
    if how == "pipe":
        assert not lines, err                     # quiet
        return
    assert lines, "no message on stderr"
    # a refusal is "hyde-bsdf CMD: ..."; a run that succeeds ends with its own "[CMD] ..." summary
    assert lines[-1].startswith((f"hyde-bsdf {argv[0]}", f"[{argv[0]}]") if code == 0 else f"hyde-bsdf {argv[0]}"), \
        lines[-1]
    assert needle in lines[-1], lines[-1]
    assert "(unexpected" not in lines[-1], lines[-1]      # every row's refusal is foreseen, never "please report it"
    assert (paths["tmp"] / "kept" / "invert_history.csv").read_text() == "a previous run's output\n"   # no file lost
    after = _snapshot(paths["tmp"])
    assert {f: b for f, b in after.items() if f in before} == before, "an existing file changed or was lost"
    assert not [f for f in after if TEMP_NAME_RE.match(Path(f).name)], "a temporary was left behind"
    if how in ("sigint", "sigterm", "sighup", "sigint-group"):
        assert not (paths["tmp"] / f"{how}.exr").exists()
        assert not list(paths["tmp"].glob(f".{how}.exr.*"))   # no temporary left behind
    if how == "stale":
        assert not any(p.exists() for p in stale)


def test_api_bad_input(paths):
    for name, call, exc_type, needle in _api_rows():
        with pytest.raises(exc_type, match=needle) as info:
            call(paths)
        assert "\n" not in str(info.value), name


def test_huge_spp_is_split_into_passes_below_mitsuba_limit():
    """--spp 10^9 on a 12 x 8 film (which segfaulted in one Mitsuba call) becomes passes of at
    most 2^26 samples (Mitsuba's own per-pass limit is 2^32), with every sample kept."""
    from hyde_bsdf.render.renderer import MAX_SAMPLES_PER_PASS, plan_passes

    sizes = plan_passes(12, 8, 10**9)
    assert sum(sizes) == 10**9
    assert max(sizes) * 96 <= MAX_SAMPLES_PER_PASS < 2**32
    assert len(sizes) == 1431 and max(sizes) - min(sizes) <= 1
    assert plan_passes(12, 8, 16) == [2] * 8                # small renders: the default 8 chunks
    assert plan_passes(12, 8, 16, chunks=3) == [6, 5, 5]
