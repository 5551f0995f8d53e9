"""Run files (es/files.py, es/runfolder.py, the policies' file names): the original ``.dat`` format and names,
safe loading, atomic writes.

A ``.dat`` file is a float32 numpy array saved with ``torch.save`` (docs/original.md, "Files"). The original
files were written with numpy 1, whose pickles name ``numpy.core.multiarray._reconstruct``; they
must load under numpy 2, while a pickle that would run code must be refused without running it.
"""

import io
import math
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from es.files import (
    METRICS_COLUMNS,
    FileFormatError,
    _numpy_safe_globals,
    atomic_write_bytes,
    load_dat,
    read_metrics,
    save_dat,
    save_npy,
    write_metrics,
)
from es.runfolder import fitness_file_name, reward_label
from policies import HebbianPolicy, NetworkSpec, StaticPolicy

ROOT = Path(__file__).resolve().parent.parent

ANT = NetworkSpec((28,), 8, squash_out=True)


def static_file_name(env, reward, population, generation):
    return StaticPolicy(ANT).file_name("weights", env, reward, population, generation)


def hebbian_file_name(env, reward, rule, init, population, role, generation):
    return HebbianPolicy(ANT, rule, init).file_name(role, env, reward, population, generation)

# --- .dat round trips ----------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(7,), (12, 5), (1362, 1)])
def test_save_and_load_dat_round_trip(tmp_path, shape):
    array = np.random.default_rng(0).standard_normal(shape).astype(np.float32)
    path = tmp_path / "weights.dat"
    save_dat(path, array)
    assert zipfile.is_zipfile(path)  # torch's zip format, as the original's torch.save
    loaded = load_dat(path)
    assert loaded.dtype == np.float32 and loaded.shape == shape
    np.testing.assert_array_equal(loaded, array)
    # what the original's evaluate scripts did must still work on our files
    np.testing.assert_array_equal(torch.load(path, weights_only=False), array)


def test_save_dat_writes_torch_saves_archive_without_torch(tmp_path):
    """The same records as torch.save (but its random serialization id), data.pkl byte for byte; torch's safe
    loader reads it; the same array gives the same file; and a training run never imports torch."""
    array = np.random.default_rng(1).standard_normal(300).astype(np.float32)
    save_dat(tmp_path / "ours.dat", array)
    torch.save(array, tmp_path / "theirs.dat")
    with zipfile.ZipFile(tmp_path / "ours.dat") as ours, zipfile.ZipFile(tmp_path / "theirs.dat") as theirs:
        mine = {name.split("/", 1)[1]: ours.read(name) for name in ours.namelist()}
        torchs = {name.split("/", 1)[1]: theirs.read(name) for name in theirs.namelist()}
        assert {name.split("/", 1)[0] for name in ours.namelist()} == {"ours"}
    assert mine == {name: data for name, data in torchs.items() if name != ".data/serialization_id"}
    with torch.serialization.safe_globals(_numpy_safe_globals()):
        np.testing.assert_array_equal(torch.load(tmp_path / "ours.dat", weights_only=True), array)
    (tmp_path / "again").mkdir()
    save_dat(tmp_path / "again" / "ours.dat", array)
    assert (tmp_path / "again" / "ours.dat").read_bytes() == (tmp_path / "ours.dat").read_bytes()
    code = ("import sys, train_static; train_static.main(['--environment', 'CartPole-v1', '--popsize', '4', "
            f"'--generations', '1', '--threads', '2', '--folder', {str(tmp_path / 'runs')!r}]); "
            "print('torch' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0 and result.stdout.strip().splitlines()[-1] == "False", result.stderr[-2000:]


def test_save_dat_stores_float32(tmp_path):
    path = tmp_path / "uniform.dat"
    save_dat(path, np.array([0.1, -0.5], dtype=np.float64))  # the original's uniform is float64
    assert torch.load(path, weights_only=False).dtype == np.float32


def test_tensor_and_float64_files_load_as_float32(tmp_path):
    torch.save(torch.tensor([1.5, -2.0]), tmp_path / "tensor.dat")
    torch.save(np.array([0.25, 3.0], dtype=np.float64), tmp_path / "double.dat")
    for name, expected in (("tensor.dat", [1.5, -2.0]), ("double.dat", [0.25, 3.0])):
        loaded = load_dat(tmp_path / name)
        assert loaded.dtype == np.float32
        np.testing.assert_array_equal(loaded, expected)


def as_numpy1_file(data: bytes) -> bytes:
    """A torch.save'd numpy array rewritten as numpy 1.x would have written it.

    numpy 2 pickles arrays through ``numpy._core.multiarray._reconstruct``; numpy 1 wrote
    ``numpy.core.multiarray``. A GLOBAL opcode is newline-terminated text, so only the length
    changes; the zip is rebuilt with the same member names.
    """
    source = zipfile.ZipFile(io.BytesIO(data))
    target_bytes = io.BytesIO()
    replaced = 0
    with zipfile.ZipFile(target_bytes, "w", compression=zipfile.ZIP_STORED) as target:
        for info in source.infolist():
            content = source.read(info.filename)
            if info.filename.endswith("data.pkl"):
                old = b"cnumpy._core.multiarray\n_reconstruct\n"
                replaced += content.count(old)
                content = content.replace(old, b"cnumpy.core.multiarray\n_reconstruct\n")
            target.writestr(info.filename, content)
    assert replaced == 1
    return target_bytes.getvalue()


def test_original_numpy1_file_loads(tmp_path):
    array = np.random.default_rng(1).standard_normal((50, 5)).astype(np.float32)
    buffer = io.BytesIO()
    torch.save(array, buffer)
    path = tmp_path / "HEBcoeffs__original.dat"
    path.write_bytes(as_numpy1_file(buffer.getvalue()))
    with zipfile.ZipFile(path) as archive:
        pickled = archive.read(next(n for n in archive.namelist() if n.endswith("data.pkl")))
    assert b"numpy.core.multiarray" in pickled and b"numpy._core" not in pickled
    np.testing.assert_array_equal(load_dat(path), array)


# --- refused files -------------------------------------------------------------------------------


class RunsACommand:
    def __init__(self, command):
        self.command = command

    def __reduce__(self):
        return os.system, (self.command,)


def test_malicious_pickle_is_refused_without_running(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "evil.dat"
    torch.save(RunsACommand(f"echo pwned > {marker}"), path)
    with pytest.raises(FileFormatError, match="refused to load .*evil.dat") as error:
        load_dat(path)
    message = str(error.value)
    assert "it asks to import posix.system" in message or "it asks to import nt.system" in message
    assert "weights_only" not in message  # never torch's advice to turn the safety off
    assert not marker.exists()


def test_unknown_class_is_refused_by_name(tmp_path):
    path = tmp_path / "object.dat"
    torch.save(FileFormatError("any object of a class that is not allow-listed"), path)
    with pytest.raises(FileFormatError, match="it asks to import es.files.FileFormatError"):
        load_dat(path)


def test_missing_file_is_reported(tmp_path):
    with pytest.raises(FileFormatError, match="nothing.dat.* does not exist"):
        load_dat(tmp_path / "nothing.dat")


@pytest.mark.parametrize("content, reason", [(b"", "is empty"),
                                             (b"not a torch file at all", "not a weight file: it was not written by"),
                                             (b"PK\x03\x04truncated", "truncated or corrupt")],
                         ids=["empty", "text", "truncated_zip"])
def test_corrupt_file_is_reported(tmp_path, content, reason):
    path = tmp_path / "corrupt.dat"
    path.write_bytes(content)
    with pytest.raises(FileFormatError, match=r"corrupt\.dat") as error:
        load_dat(path)
    assert reason in str(error.value) and "weights_only" not in str(error.value)


def test_truncated_real_file_is_reported(tmp_path):
    path = tmp_path / "cut.dat"
    save_dat(path, np.arange(1000, dtype=np.float32))
    path.write_bytes(path.read_bytes()[:300])
    with pytest.raises(FileFormatError, match="cut.dat"):
        load_dat(path)


def test_a_file_that_is_not_an_array_is_refused(tmp_path):
    path = tmp_path / "dict.dat"
    torch.save({"weights": [1, 2]}, path)
    with pytest.raises(FileFormatError, match="holds a dict, not a numeric array"):
        load_dat(path)


# --- atomic writes -------------------------------------------------------------------------------


def test_atomic_write_replaces_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "config.json"
    atomic_write_bytes(path, b"first")
    atomic_write_bytes(path, b"second, longer content")
    assert path.read_bytes() == b"second, longer content"
    assert os.listdir(tmp_path) == ["config.json"]


def test_failed_atomic_write_keeps_the_old_file(tmp_path):
    path = tmp_path / "metrics.csv"
    atomic_write_bytes(path, b"old content")
    with pytest.raises(TypeError):
        atomic_write_bytes(path, "text is not bytes")  # the write itself fails, mid-way
    assert path.read_bytes() == b"old content"
    assert os.listdir(tmp_path) == ["metrics.csv"]


# --- the original names (docs/original.md, "Files") ----------------------------------------------------------------


def test_atomic_write_never_replaces_a_folder(tmp_path):
    target = tmp_path / "folder"
    target.mkdir()
    with pytest.raises(OSError, match="is not a regular file"):
        atomic_write_bytes(target, b"x")
    assert target.is_dir() and list(tmp_path.iterdir()) == [target]


def test_original_file_names():
    assert static_file_name("AntBulletEnv-v0", 1523, 200, 299) == "AntBulletEnv-v0__rew_1523__pop_200__299.dat"
    assert static_file_name("Pendulum-v1", -12, 10, 0) == "Pendulum-v1__rew_-12__pop_10__0.dat"
    assert (hebbian_file_name("CarRacing-v3", 871, "ABCD_lr", "uni", 200, "coeffs", 99)
            == "HEBcoeffs__CarRacing-v3__rew_871__ABCD_lr__init_uni__pop_200__coeffs__99.dat")
    assert (hebbian_file_name("CarRacing-v3", 871, "ABCD_lr", "uni", 200, "CNN_parameters", 99)
            == "HEBcoeffs__CarRacing-v3__rew_871__ABCD_lr__init_uni__pop_200__CNN_parameters__99.dat")
    assert (hebbian_file_name("AntBulletEnv-v0", 2000, "A", "coevolve", 100, "coevolved_initial_weights", 4)
            == "HEBcoeffs__AntBulletEnv-v0__rew_2000__A__init_coevolve__pop_100__coevolved_initial_weights__4.dat")
    assert fitness_file_name("1600000000", "AntBulletEnv-v0") == "Fitness_values_1600000000_AntBulletEnv-v0.npy"


def test_reward_labels_are_the_originals_and_short_whatever_the_reward():
    assert [reward_label(value) for value in (1523.9, -12.7, 0.4, 999_999_999_999_999.0)] == [1523, -12, 0,
                                                                                              999_999_999_999_999]
    assert [reward_label(value) for value in (1e15, -1.712e308, math.nan, -math.inf)] == ["1e+15", "-1.71e+308", 0, 0]
    assert (static_file_name("CartPole-v1", reward_label(-1.712e308), 4, 0)
            == "CartPole-v1__rew_-1.71e+308__pop_4__0.dat")


def test_a_run_whose_fitness_is_huge_keeps_its_file_names_short(tmp_path):
    """--fitness_l2 at its limit: the fitness is about -5e36, a 37-digit integer part."""
    import train_static

    assert train_static.main(["--environment", "CartPole-v1", "--popsize", "4", "--generations", "1", "--threads",
                              "1", "--seed", "1", "--fitness_l2", "3e38", "--folder", str(tmp_path)]) == 0
    (run_dir,) = tmp_path.iterdir()
    (weights,) = run_dir.glob("CartPole-v1__rew_*.dat")
    assert re.fullmatch(r"CartPole-v1__rew_-\d\.\d\de\+36__pop_4__0\.dat", weights.name), weights.name
    assert max(len(path.name) for path in run_dir.iterdir()) < 80


def test_fitness_file_round_trip(tmp_path):
    path = tmp_path / fitness_file_name("17", "CartPole-v1")
    save_npy(path, np.array([10.5, 20.25, 31.0]))
    np.testing.assert_array_equal(np.load(path), [10.5, 20.25, 31.0])


# --- metrics.csv ---------------------------------------------------------------------------------


def metrics_row(generation):
    row = {name: 0.1 * (index + 1) + generation for index, name in enumerate(METRICS_COLUMNS)}
    row.update(generation=generation, skipped=False, nonfinite=0, env_steps=1234, total_env_steps=5678)
    return row


def test_metrics_round_trip(tmp_path):
    path = tmp_path / "metrics.csv"
    rows = [metrics_row(1), metrics_row(2), metrics_row(3)]
    write_metrics(path, [dict(row, extra="ignored") for row in rows])
    read = read_metrics(path)
    assert path.read_text().splitlines()[0] == ",".join(METRICS_COLUMNS)
    assert [list(row) for row in read] == [list(METRICS_COLUMNS)] * 3
    for written, back in zip(rows, read):
        assert int(back["generation"]) == written["generation"]
        assert float(back["fitness_mean"]) == written["fitness_mean"]  # floats survive exactly
        assert float(back["lr"]) == written["lr"]
        assert back["skipped"] == "False"
    write_metrics(path, rows[:1])  # a resume rewrites the file without the later rows
    assert len(read_metrics(path)) == 1
    assert os.listdir(tmp_path) == ["metrics.csv"]


def test_metrics_row_missing_a_column_is_an_error(tmp_path):
    row = metrics_row(1)
    del row["sigma"]
    with pytest.raises(KeyError, match="sigma"):
        write_metrics(tmp_path / "metrics.csv", [row])
