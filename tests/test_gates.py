"""The one memory check (``hyde_bsdf.resources``) and the file gates (``hyde_bsdf.io``).

Each refusal is a UsageError whose one line names the file and the reason, and leaves the file
system as it was (contents, modes, special files).  The command-level rows are in
``tests/test_bad_inputs.py``.
"""
import os
import stat
import subprocess
import sys
import threading

import pytest

from hyde_bsdf.errors import UsageError
from hyde_bsdf import resources
from hyde_bsdf.io import input_gate, output_gate


# ---- memory

@pytest.mark.parametrize("n, text", [(0, "0 B"), (512, "512 B"), (1536, "1.5 KiB"), (150 * 2**20, "150 MiB"),
                                     (int(74.5 * 2**30), "74.5 GiB"), (3 * 2**40, "3 TiB")])
def test_sizes_are_printed_in_units_that_show_them(n, text):
    assert resources.format_bytes(n) == text


def test_memory_refusal_names_what_and_the_remedy_never_zero_gib(monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: 2**20)
    with pytest.raises(UsageError) as exc:
        resources.check_memory(3 * 2**20, "the 100000x100000 maps", "lower map_size")
    msg = str(exc.value)
    assert "3 MiB" in msg and "1 MiB" in msg and "map_size" in msg and "0.00" not in msg
    assert resources.check_memory(2**20, "x", "y") == 2**20


def test_meminfo_is_read_in_one_place(tmp_path, monkeypatch):
    fake = tmp_path / "meminfo"
    fake.write_text("MemTotal:       16000 kB\nMemAvailable:    8000 kB\n")
    monkeypatch.setattr(resources, "MEMINFO", str(fake))
    assert resources.available_memory() == 8000 * 1024 and resources.total_memory() == 16000 * 1024


def test_no_other_module_reads_proc_meminfo():
    import hyde_bsdf
    from pathlib import Path
    root = Path(hyde_bsdf.__file__).parent
    readers = [str(p.relative_to(root)) for p in root.rglob("*.py")
               if "/proc/meminfo" in p.read_text() and p.name != "resources.py"]
    assert readers == []


# ---- input gate

def test_fifo_device_and_folder_inputs_are_refused_without_opening(tmp_path):
    fifo = tmp_path / "x.csv"
    os.mkfifo(fifo)
    for path, kind in ((fifo, "FIFO"), ("/dev/zero", "character device"), (tmp_path, "directory")):
        with pytest.raises(UsageError, match=kind):
            input_gate.read_input(path, "measurement file")     # would block or never end if opened
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_size_limit_is_checked_before_reading(tmp_path):
    big = tmp_path / "big.csv"
    big.write_bytes(b"1," * 600)
    with pytest.raises(UsageError, match="1.17 KiB, more than the 1 KiB"):
        input_gate.read_input(big, "measurement file", limit=1024)


def test_stdin_is_read_once_whole():
    """`cat x.csv | fit /dev/stdin` must not lose bytes: the gate reads the pipe once, whole."""
    code = ("import sys; from hyde_bsdf.io.input_gate import read_text; "
            "t = read_text('/dev/stdin', 'csv'); sys.stdout.write(str(len(t)) + ':' + t[:12])")
    data = "theta_i_deg,theta_r_deg\n" + "10,20\n" * 1000
    out = subprocess.run([sys.executable, "-c", code], input=data, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": os.getcwd()}, check=True).stdout
    assert out == f"{len(data)}:theta_i_deg,"


def test_a_huge_csv_cell_is_one_line_naming_the_row():
    text = "a,b\n1,2\n3," + "9" * 200_000 + "\n"
    with pytest.raises(UsageError, match=r"row 3: a field is longer than the 4096 characters accepted") as exc:
        input_gate.csv_rows(text, "measurement file")
    assert "\n" not in str(exc.value) and len(str(exc.value)) < 300


def test_table_dimensions_overflow_and_memory_are_checked_before_allocation():
    dims = (2**40, 2**40, 2**40)      # the product overflows int64; Python integers do not
    with pytest.raises(UsageError, match="file holds only"):
        input_gate.check_dimensions(dims, 4, "pbsdf table", available_in_file=10**6)
    with pytest.raises(UsageError, match="of memory needed"):
        input_gate.check_dimensions((2**20, 2**20), 8, "pbsdf table")
    assert input_gate.check_dimensions((3, 4), 8, "pbsdf table", available_in_file=96) == 96


def test_long_values_are_cut_in_messages():
    from hyde_bsdf.errors import shorten
    text = shorten("A" * 100_000)
    assert len(text) < 120 and "[99924 characters]" in text


# ---- output gate

@pytest.mark.parametrize("make, kind", [
    (lambda p: os.mkfifo(p), "FIFO"),
    (lambda p: p.mkdir(), "directory"),
    (lambda p: os.symlink("/dev/null", p), "symbolic link"),
    (lambda p: os.symlink("/proc/self/fd/1", p), "symbolic link"),
    (lambda p: os.symlink("../outside.txt", p), "symbolic link"),
], ids=["fifo", "folder", "link-dev-null", "link-proc-fd", "link-up"])
def test_existing_special_targets_are_refused_and_left_as_they_are(tmp_path, make, kind):
    out = tmp_path / "out" / "a.exr"
    out.parent.mkdir()
    make(out)
    before = os.lstat(out)
    with pytest.raises(UsageError, match=kind):
        output_gate.check_target(out)
    after = os.lstat(out)
    assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)


def test_device_target_is_refused():
    with pytest.raises(UsageError, match="character device"):
        output_gate.check_target("/dev/null")


def test_symlink_inside_the_folder_writes_the_file_it_names(tmp_path):
    (tmp_path / "real.csv").write_text("old")
    os.symlink("real.csv", tmp_path / "link.csv")
    assert output_gate.check_target(tmp_path / "link.csv") == (tmp_path / "real.csv").resolve()


def test_an_input_of_the_same_run_is_never_an_output(tmp_path):
    scene = tmp_path / "alpha.exr"
    scene.write_bytes(b"texture")
    os.link(scene, tmp_path / "hardlink.exr")
    for out in (scene, tmp_path / "." / "alpha.exr", tmp_path / "hardlink.exr"):
        with pytest.raises(UsageError, match="is the input"):
            output_gate.check_not_input([out], [scene])
    assert scene.read_bytes() == b"texture"


def test_free_space_is_checked_before_the_work(tmp_path):
    with pytest.raises(UsageError, match=r"about 1 EiB needed, but .* free; free some space"):
        output_gate.check_free_space(tmp_path / "new", 2**60)


def test_a_replaced_file_keeps_its_mode(tmp_path):
    from hyde_bsdf.io.atomic import atomic_open
    target = tmp_path / "secret.csv"
    target.write_text("old")
    os.chmod(target, 0o600)
    with atomic_open(target) as fh:
        fh.write("new")
    assert target.read_text() == "new" and stat.S_IMODE(os.stat(target).st_mode) == 0o600


def test_concurrent_writers_of_one_output_fail_fast(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    (tmp_path / "run").mkdir(mode=0o700)
    target = tmp_path / "render.exr"
    with resources.OutputLock([target], "render output"):
        err = []
        t = threading.Thread(target=lambda: _try_lock(target, err))
        t.start()
        t.join()
        assert len(err) == 1 and f"pid {os.getpid()}" in err[0] and "another run" in err[0]
    with resources.OutputLock([target]):      # released: free again
        pass


def _try_lock(target, err):
    try:
        with resources.OutputLock([target], "render output"):
            pass
    except UsageError as exc:
        err.append(str(exc))


def test_output_gate_yields_the_checked_targets(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    (tmp_path / "run").mkdir(mode=0o700)
    with output_gate.output_gate([tmp_path / "a.csv", tmp_path / "b.png"], inputs=[tmp_path / "in.csv"]) as t:
        assert t == [tmp_path / "a.csv", tmp_path / "b.png"]
