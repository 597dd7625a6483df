"""read_csv on hostile or sloppy input: strict numbers, negative values, empty rows, line endings,
encodings, size limits and files that are not regular files (docs/tables.md, "Bad values")."""

import os
import re
import signal
import tracemalloc
from contextlib import contextmanager

import numpy as np
import pytest

from appearance_jax.fit.tables import csv_table
from appearance_jax.fit.tables.csv_table import TableError, read_csv
from appearance_jax.fit.tables.io import read_table

HEAD = "# appearance-jax table v1\n# quantity: brdf\n"
FULL = "theta_i,phi_i,theta_o,phi_o,R,G,B\n"
SIG = "theta_i,theta_o,R,G,B,sigma_R,sigma_G,sigma_B\n"


needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo") or not hasattr(signal, "SIGALRM"),
                                reason="needs os.mkfifo and SIGALRM (POSIX)")


@contextmanager
def deadline(seconds=10):
    """Fail (not hang) when the body blocks, e.g. opening a FIFO nobody writes to."""
    def _expired(signum, frame):
        raise TimeoutError(f"blocked for more than {seconds} s")

    old = signal.signal(signal.SIGALRM, _expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _write(tmp_path, text, name="t.csv"):
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return p


BAD = [
    # (file text, line, regex of the problem): every message names the column and the cell text
    (HEAD + FULL + "30,0,30,180,1_0,1,1\n", 4, re.escape("R = '1_0' is not a plain number (digit separators '_'")),
    (HEAD + FULL + "3_0,0,30,180,1,1,1\n", 4, re.escape("theta_i = '3_0' is not a plain number (digit separators")),
    (HEAD + SIG + "30,30,1,1,1,0.1,0_1,0.1\n", 4, re.escape("sigma_G = '0_1' is not a plain number")),
    (HEAD + FULL + "30deg,0,30,180,1,1,1\n", 4, re.escape("theta_i = '30deg' is not a plain number (unit or text "
                                                          "'deg' after 30?")),
    (HEAD + FULL + "30,0,45 °,180,1,1,1\n", 4,
     re.escape("theta_o = '45 °' is not a plain number (unit or text '°'")),
    (HEAD + FULL + "30,0,30,180,0.5 1/sr,1,1\n", 4, re.escape("R = '0.5 1/sr' is not a number")),
    (HEAD + FULL + "30,0,30,180,12%,1,1\n", 4, re.escape("R = '12%' is not a plain number (unit or text '%'")),
    (HEAD + FULL + "30,0,30,180,1,\u0661\u0660,1\n", 4, "G = '.*' is not a plain number \\(write ASCII digits"),
    (HEAD + FULL + "30,0,30,180,1,0x10,1\n", 4, re.escape("G = '0x10' is not a plain number")),
    (HEAD + FULL + "30,0,30,180,1,1,infinity\n", 4, re.escape("B = infinity is not finite")),
    (HEAD + FULL + "30,0,30,180,1,1,-nan\n", 4, re.escape("B = -nan is not finite")),
    (HEAD + FULL + "30,0,30,180,1,1,1e999\n", 4, re.escape("B = 1e999 is not finite")),
    (HEAD + FULL + "30,0,30,180,1,1,1.2.3\n", 4, re.escape("B = '1.2.3' is not a number")),
    ("# quantity: reflectance_factor\n# white_reference: 0_99\n" + FULL, 2,
     re.escape("white_reference = '0_99' is not a number")),
    (HEAD + "theta_i,theta_o,4_50,550\n", 3, re.escape("unknown column '4_50'")),
    (HEAD + "theta_i,theta_o,450nm,550nm\n", 3,
     re.escape("unknown column '450nm' (") + ".*" + re.escape("named by its number in nm alone, e.g. '450')")),
    (HEAD + FULL + "30,0,30,180,,,\n30,0,40,180,nan,NA,\n", 3, re.escape("no valid value in the 2 data rows")),
    (HEAD + FULL + "30,0,30,180,-1,-1,-1\n30,0,40,180,,,\n", 3, "no valid value .*missing or negative"),
    (HEAD + FULL + "30,0,30,180,1,1,1\n30,0,30,180,2,2,2\n", 5, re.escape("duplicate of line 4")),
    (HEAD + FULL + "30,0,30,180,1,1\n", 4, re.escape("row has 6 cells, expected 7")),
    (HEAD + FULL, 3, "no data rows after the column header"),
    ("", 1, "empty file"),
    (HEAD.replace("\n", "\r") + FULL.replace("\n", "\r") + "30,0,30,180,1,1,1\r30,0,95,180,1,1,1\r", 5,
     re.escape("theta_o = 95 is outside [0, 90] degrees")),
    (HEAD + "\r\n" + FULL + "\r30,0,30,180,1,x,1\n", 6, re.escape("G = 'x' is not a number")),
    (HEAD + FULL + "30,0,30,180,1,1,1\n\0\0\0", 5, "NUL character: a binary file, not CSV text"),
    ("# quantity: brdf\n".encode("utf-16"), 1,
     re.escape("UTF-16 text (a byte-order mark 0xfffe); save the table as UTF-8")),
    (HEAD.encode() + b"\r# sample: \xe9chantillon\r" + FULL.encode(), 4, re.escape("not UTF-8 text (byte 0xe9)")),
    (b"\xef\xbb\xbf" + HEAD.encode() + b"# \xff\n", 3, re.escape("not UTF-8 text (byte 0xff)")),  # after a BOM
]


@pytest.mark.parametrize("text,line,problem", BAD, ids=[f"{i}" for i in range(len(BAD))])
def test_bad_input_raises_naming_file_line_and_cell(tmp_path, text, line, problem):
    p = _write(tmp_path, text, name="bad_input.csv")
    with pytest.raises(TableError, match="^" + re.escape(f"{p}:{line}: ") + ".*" + problem):
        read_csv(p)


def test_negative_values_are_masked_and_counted(tmp_path):
    p = _write(tmp_path, HEAD + SIG + "30,30,0.5,-0.01,0.2,0.1,0.1,0.1\n"
                                      "30,-30,-1,-1,-1,0,0,0\n"
                                      "30,0,0.5,0.4,-0.0,0.1,0.1,0.1\n")
    t = read_csv(p)
    np.testing.assert_array_equal(t.mask, [[1, 0, 1], [0, 0, 0], [1, 1, 1]])  # -0.0 is zero, not negative
    assert t.masked == {"negative value": 4}
    assert np.all(np.isnan(t.values[~t.mask])) and np.all(np.isnan(t.sigma[~t.mask]))
    assert "4 negative value" in t.summary()


def test_negative_values_written_are_read_back_masked(tmp_path):
    from appearance_jax.fit.tables.csv_table import write_csv
    from appearance_jax.fit.tables.table import Table

    t = Table.in_plane(np.deg2rad([10.0, 20.0]), np.deg2rad([-10.0, 20.0]), np.array([[0.1, -1e-3, 0.2],
                                                                                       [0.3, 0.4, 0.5]]))
    write_csv(t, tmp_path / "neg.csv")
    back = read_csv(tmp_path / "neg.csv")
    assert back.masked == {"negative value": 1} and not back.mask[0, 1] and back.n_valid == 5


def test_rows_without_any_value_are_counted_apart(tmp_path):
    p = _write(tmp_path, HEAD + FULL + "30,0,30,180,1,,1\n30,0,40,180,,nan,NA\n30,0,50,180,,,\n"
                                       "30,0,60,180,1,1,-2\n")
    t = read_csv(p)
    assert t.n_samples == 4 and t.n_valid == 4
    assert t.masked == {"missing value": 1, "missing value (whole row)": 6, "negative value": 1}


def test_masked_reasons_reach_the_fit_problem(tmp_path):
    """The counts the report lists (params.json "masked") come from the table's reasons."""
    from appearance_jax.fit.solve.problem import build_problem

    rows = "".join(f"{ti},0,{to},180,0.3,0.3,0.3\n" for ti in (10, 30) for to in (10, 20, 40))
    p = _write(tmp_path, HEAD + FULL + rows + "30,0,60,180,-0.1,0.3,0.3\n30,0,70,180,,,\n")
    problem = build_problem("lambert", read_csv(p), max_theta_deg=None)
    assert problem.masked == {"missing value (whole row)": 3, "negative value": 1}


@pytest.mark.parametrize("eol,bom", [("\n", ""), ("\r\n", "\ufeff"), ("\r", ""), ("\r", "\ufeff")])
def test_line_endings_lf_crlf_and_cr_only_read_alike(tmp_path, eol, bom):
    text = bom + HEAD + "# note\n" + FULL + "30,0,30,180,0.1,0.2,0.3\n30,0,40,180,0.4,,0.6\n"
    t = read_csv(_write(tmp_path, text.replace("\n", eol)))
    assert t.n_samples == 2 and t.masked == {"missing value": 1}
    np.testing.assert_allclose(t.values[0], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(np.rad2deg(t.theta_o), [30, 40])


def test_size_limit_is_checked_before_reading_and_can_be_raised(tmp_path, monkeypatch):
    body = HEAD + FULL + "".join(f"30,0,{to},180,1,1,1\n" for to in range(60))
    p = _write(tmp_path, body)
    n = len(body.encode())
    with pytest.raises(TableError, match="^" + re.escape(f"{p}: file has {n} bytes, more than the limit of "
                                                        f"{n - 1} bytes (read_csv(path, max_bytes=...)")):
        read_csv(p, max_bytes=n - 1)
    assert read_csv(p, max_bytes=n).n_samples == 60
    with pytest.raises(TableError, match="more than the limit"):
        read_table(str(p), max_bytes=100)
    monkeypatch.setattr(csv_table, "MAX_CSV_BYTES", 100)  # the default limit
    with pytest.raises(TableError, match="limit of 100 bytes"):
        read_csv(p)


def test_oversized_file_is_refused_without_reading_it(tmp_path):
    p = tmp_path / "huge.csv"
    with open(p, "wb") as f:  # sparse: 200 MB on paper, nothing on disk
        f.write((HEAD + FULL).encode())
        f.truncate(200 * 2**20)
    tracemalloc.start()
    try:
        with pytest.raises(TableError, match=re.escape(f"{p}: file has {200 * 2**20} bytes, more than the limit")):
            read_csv(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20  # the 200 MB were never read


@needs_fifo
def test_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    with deadline(10):
        with pytest.raises(TableError, match="^" + re.escape(f"{fifo}: is a FIFO (named pipe), not a regular file")):
            read_csv(fifo)
        with pytest.raises(TableError, match="FIFO"):
            read_table(str(fifo))


@needs_fifo
def test_device_is_refused(tmp_path):
    # /dev/null, not /dev/zero: a regression must fail, not read an endless device into memory
    if not os.path.exists("/dev/null"):
        pytest.skip("no /dev/null")
    with deadline(10):
        with pytest.raises(TableError, match=re.escape("/dev/null: is a character device, not a regular file")):
            read_csv("/dev/null")
