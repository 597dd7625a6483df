"""Every file loader checks the kind and the size of a file before reading it: MERL ``.binary``
(header and size before the body), the refractiveindex.info YAML loader, read_table. A FIFO,
a device or a huge file is an error at once, never a hang or a large read."""

import os
import re
import tracemalloc

import numpy as np
import pytest

from appearance_jax.core.files import FileProblem, read_regular_file
from appearance_jax.fit.tables.csv_table import TableError
from appearance_jax.fit.tables.io import read_table
from appearance_jax.fit.tables.merl import MERL_FILE_BYTES, read_merl
from appearance_jax.optics.refractiveindex_yaml import load_refractiveindex_yaml

from .test_csv_bad_input import deadline, needs_fifo

MERL_HEADER = np.array([90, 90, 180], "<i4").tobytes()


def _sparse(path, head: bytes, size: int):
    """A file of ``size`` bytes starting with ``head``, sparse (costs no disk)."""
    with open(path, "wb") as f:
        f.write(head)
        f.truncate(size)
    return path


def _peak_bytes(fn):
    """Peak Python allocation while fn() raises (the error is returned)."""
    tracemalloc.start()
    try:
        with pytest.raises(Exception) as err:
            fn()
        return tracemalloc.get_traced_memory()[1], err.value
    finally:
        tracemalloc.stop()


def test_merl_bad_header_of_a_large_file_is_refused_without_reading_the_body(tmp_path):
    p = _sparse(tmp_path / "big.binary", np.array([1, 2, 3], "<i4").tobytes(), 600 * 10**6)
    peak, err = _peak_bytes(lambda: read_merl(p))
    assert isinstance(err, TableError)
    assert str(err).startswith(f"{p}: MERL header gives bin counts (1, 2, 3), expected (90, 90, 180)")
    assert peak < 2**20  # not the 600 MB body


@pytest.mark.parametrize("extra", [10**8, -8])
def test_merl_wrong_size_gives_expected_and_actual_bytes_before_reading(tmp_path, extra):
    p = _sparse(tmp_path / "size.binary", MERL_HEADER, MERL_FILE_BYTES + extra)
    peak, err = _peak_bytes(lambda: read_merl(p))
    assert isinstance(err, TableError)
    assert str(err).startswith(f"{p}: file has {MERL_FILE_BYTES + extra} bytes, expected {MERL_FILE_BYTES} "
                               "(12-byte header + 3 x 90 x 90 x 180 float64)")
    assert peak < 2**20


@needs_fifo
def test_merl_fifo_and_device_are_refused_promptly(tmp_path):
    fifo = tmp_path / "pipe.binary"
    os.mkfifo(fifo)
    with deadline(10):
        with pytest.raises(TableError, match="^" + re.escape(f"{fifo}: is a FIFO (named pipe), not a regular file "
                                                            "(a MERL .binary file is expected)")):
            read_merl(fifo)
        with pytest.raises(TableError, match="FIFO"):
            read_table(str(fifo))
        if os.path.exists("/dev/null"):  # not /dev/zero: a regression must not read an endless device
            with pytest.raises(TableError, match=re.escape("/dev/null: is a character device")):
                read_merl("/dev/null")


def test_merl_directory_and_missing_file(tmp_path):
    d = tmp_path / "dir.binary"
    d.mkdir()
    with pytest.raises(TableError, match=re.escape(f"{d}: is a directory, not a regular file")):
        read_merl(d)
    with pytest.raises(FileNotFoundError):
        read_merl(tmp_path / "nope.binary")


@needs_fifo
def test_yaml_loader_refuses_fifo_huge_and_non_utf8_files(tmp_path, monkeypatch):
    import appearance_jax.optics.refractiveindex_yaml as ri

    fifo = tmp_path / "pipe.yml"
    os.mkfifo(fifo)
    prefix = f"refractiveindex.info file {fifo}: "
    with deadline(10):
        with pytest.raises(ValueError, match="^" + re.escape(prefix + "is a FIFO (named pipe), not a regular file")):
            load_refractiveindex_yaml(fifo)
    big = _sparse(tmp_path / "big.yml", b"DATA:\n", 2 * ri.MAX_YAML_BYTES)
    peak, err = _peak_bytes(lambda: load_refractiveindex_yaml(big))
    assert isinstance(err, ValueError) and peak < 2**20
    assert str(err) == (f"refractiveindex.info file {big}: file has {2 * ri.MAX_YAML_BYTES} bytes, more than "
                        f"the limit of {ri.MAX_YAML_BYTES} bytes")
    latin = tmp_path / "latin1.yml"
    latin.write_bytes(b"REFERENCES: \"Ch\xe9mistry\"\nDATA:\n  - type: formula 5\n")
    with pytest.raises(ValueError, match="^" + re.escape(f"refractiveindex.info file {latin}: is not UTF-8 text "
                                                         "(byte 0xe9 on line 1)")):
        load_refractiveindex_yaml(latin)


def test_read_regular_file_limit_and_kind(tmp_path):
    p = tmp_path / "x.bin"
    p.write_bytes(b"12345")
    assert read_regular_file(p, 5) == b"12345"
    with pytest.raises(FileProblem, match=re.escape("file has 5 bytes, more than the limit of 4 bytes")):
        read_regular_file(p, 4)
    with pytest.raises(FileProblem, match="is a directory"):
        read_regular_file(tmp_path)


@needs_fifo
def test_writers_refuse_a_fifo_or_directory_instead_of_blocking(tmp_path):
    from appearance_jax.fit.tables.csv_table import write_csv
    from appearance_jax.fit.tables.merl import write_merl
    from appearance_jax.fit.tables.table import Table

    fifo = tmp_path / "out.pipe"
    os.mkfifo(fifo)
    t = Table.in_plane([0.1], [0.2], np.ones((1, 3)))
    with deadline(10):
        with pytest.raises(ValueError, match=re.escape(f"write_csv: {fifo} is a FIFO (named pipe), not a regular "
                                                       "file to write to")):
            write_csv(t, fifo)
        with pytest.raises(ValueError, match=re.escape(f"write_merl: {tmp_path} is a directory")):
            write_merl(tmp_path, np.zeros((90, 90, 180, 3)))
