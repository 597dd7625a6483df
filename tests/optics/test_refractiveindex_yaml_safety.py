"""The refractiveindex.info YAML loader on hostile input: every text of <= 1 KB is answered
at once (aliases and anchors refused, nesting and size capped) and nothing is ever executed.
A regression fails through the alarm below instead of hanging the test run."""

import re
import signal

import pytest

import appearance_jax.optics.refractiveindex_yaml as ri
from appearance_jax.optics.refractiveindex_yaml import parse_refractiveindex_yaml

# 8 lines that stand for 9^7 = 4.8 million strings; str() of the "type" took > 30 s before
BILLION_LAUGHS = """\
a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
DATA: [{type: *g}]
"""
assert len(BILLION_LAUGHS) <= 1024

HOSTILE = {
    "billion_laughs": (BILLION_LAUGHS, r"uses a YAML anchor or alias \(line 1\)"),
    "one_alias": ("x: &n 1.5\nDATA:\n  - type: formula 5\n    wavelength_range: 0.4 0.8\n    coefficients: *n\n",
                  r"anchor or alias \(line 1\)"),
    "merge_key": ("base: &b {type: formula 5}\nDATA:\n  - <<: *b\n    coefficients: 1.5\n", r"anchor or alias"),
    "deep_lists": ("DATA: " + "[" * 500 + "]" * 500 + "\n", r"more than 32 levels deep"),
    "deep_maps": ("DATA: " + "{a: " * 200 + "1" + "}" * 200 + "\n", r"more than 32 levels deep"),
    "python_tag": ('DATA: !!python/object/apply:os.system ["echo pwned"]\n', r"is not valid YAML"),
    "two_documents": ("DATA: []\n---\nDATA: []\n", r"is not valid YAML"),
    "unclosed_quote": ('DATA: [{type: "formula 5}]\n', r"is not valid YAML"),
    "tab_indent": ("DATA:\n\t- type: formula 5\n", r"is not valid YAML"),
    "type_is_a_list": ("DATA:\n  - type: [1, 2, 3]\n", r"unsupported type"),
    "huge_number": ("DATA:\n  - type: formula 5\n    wavelength_range: 0.4 0.8\n    coefficients: 1e999\n",
                    r"non-finite coefficients"),
    "long_digits": ("DATA:\n  - type: formula " + "9" * 900 + "\n", r"unsupported type"),
    "empty": ("", r"no DATA section"),
    "scalar": ("42\n", r"no DATA section"),
}


@pytest.fixture
def alarm():
    def _expired(signum, frame):
        raise TimeoutError("parse_refractiveindex_yaml blocked for more than 10 s")

    if not hasattr(signal, "SIGALRM"):  # not POSIX: no hard bound, the test still runs
        yield
        return
    old = signal.signal(signal.SIGALRM, _expired)
    signal.alarm(10)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_yaml_is_refused_at_once(case, alarm, capfd):
    text, pattern = HOSTILE[case]
    assert len(text.encode()) <= 1024
    with pytest.raises(ValueError, match="^" + re.escape(f"refractiveindex.info file <{case}>: ") + ".*" + pattern):
        parse_refractiveindex_yaml(text, source=f"<{case}>")
    assert "pwned" not in capfd.readouterr().out  # nothing was executed


def test_text_size_is_capped(monkeypatch):
    monkeypatch.setattr(ri, "MAX_YAML_BYTES", 100)
    with pytest.raises(ValueError, match="has 101 characters, more than the limit of 100"):
        parse_refractiveindex_yaml("#" * 101, source="<big>")
    with pytest.raises(ValueError, match="text must be a str, got bytes"):
        parse_refractiveindex_yaml(b"DATA: []", source="<bytes>")

