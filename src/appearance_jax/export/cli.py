"""``appearance-jax export``: a fit's ``params.json`` -> a renderer's material file.

    appearance-jax export out/fit/params.json --format mitsuba --out gold.xml
    appearance-jax export out/fit/params.json --dict --out gold.json --approximate

Writes the fitted material as a Mitsuba 3 BSDF (:mod:`appearance_jax.export.mitsuba`; the
mapping of every parameter is in ``docs/export.md``): ``--xml`` (default, or when ``--out``
does not end in ``.json``) a standalone ``<bsdf>`` element (``mitsuba.load_file`` loads it;
paste it into a scene and ``<ref id="ID"/>`` it), ``--dict`` (default for ``--out X.json``)
the ``mitsuba.load_dict`` dict as JSON. Without ``--out`` the text goes to stdout. Every
option is checked before the record is read; a setting Mitsuba cannot reproduce (e.g. the
default height-correlated Smith G2) is an error unless ``--approximate``, which writes the
nearest Mitsuba BSDF and lists what differs on stderr (and in the XML's comment).

This module provides ``add_parser(subparsers)`` and ``run(args)``, the interface of the
command modules of :mod:`appearance_jax.cli`.
"""

from __future__ import annotations

import json
import os
import sys

NAME = "export"
FORMATS = ("mitsuba",)


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        NAME, help="write a fitted material (params.json) as a Mitsuba 3 BSDF (XML or load_dict JSON)",
        description="Write the material of a fit's params.json as a renderer's BSDF. Mitsuba 3: lambert, "
                    "rough_conductor, rough_dielectric, rough_plastic, their sums (blendbsdf) and chiang_hair; "
                    "the parameter mapping is in docs/export.md.")
    p.add_argument("params_json", metavar="PARAMS_JSON", help="the params.json written by appearance-jax fit --out DIR")
    p.add_argument("--format", choices=FORMATS, default="mitsuba", help="target renderer (default mitsuba)")
    kind = p.add_mutually_exclusive_group()
    kind.add_argument("--xml", dest="kind", action="store_const", const="xml",
                      help="Mitsuba XML <bsdf> element (default unless --out ends in .json)")
    kind.add_argument("--dict", dest="kind", action="store_const", const="dict",
                      help="the mitsuba.load_dict dict, as JSON (default for --out *.json)")
    p.add_argument("--approximate", action="store_true",
                   help="export settings Mitsuba has no equivalent for (e.g. shadowing=correlated) as the nearest "
                        "Mitsuba BSDF, listing the differences on stderr (default: refuse)")
    p.add_argument("--id", default="material", help="XML id of the <bsdf> element (default material)")
    p.add_argument("--out", default=None, metavar="FILE", help="output file (default: stdout); overwritten if present")
    p.set_defaults(fn=run)


def _check_options(args) -> str:
    """The output kind ('xml' or 'dict'); a ValueError naming the option otherwise."""
    import re

    from ..core.files import FileProblem, check_output_path
    from .mitsuba import ExportError

    if args.format not in FORMATS:
        raise ExportError(f"--format {args.format!r}: valid formats are {', '.join(FORMATS)}")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", args.id):
        raise ExportError(f"--id {args.id!r}: give a name of letters, digits, '_', '.', '-' (not starting with a digit)")
    src = args.params_json
    if not os.path.exists(src):
        raise ExportError(f"PARAMS_JSON {src!r}: no such file")
    if os.path.isdir(src):
        raise ExportError(f"PARAMS_JSON {src!r} is a directory; give the params.json file in it "
                          f"({os.path.join(src, 'params.json')})")
    out = args.out
    if out is not None:
        if out == "" or os.path.isdir(out) or out.endswith(os.sep):
            raise ExportError(f"--out {out!r} is a directory; give a file name (e.g. {os.path.join(out or '.', 'material.xml')})")
        parent = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(parent):
            raise ExportError(f"--out {out!r}: the folder {parent!r} does not exist")
        if os.path.abspath(out) == os.path.abspath(src):
            raise ExportError(f"--out {out!r} is the input PARAMS_JSON; give another file")
        try:
            check_output_path(out)  # a FIFO or a device would block or never be meant
        except FileProblem as e:
            raise ExportError(f"--out {out!r} {e.problem}") from None
    if args.kind is not None:
        return args.kind
    return "dict" if out is not None and out.lower().endswith(".json") else "xml"


def _check_bands(rec: dict, path: str) -> None:
    table = rec.get("table") if isinstance(rec.get("table"), dict) else {}
    wl = table.get("wavelengths_nm")
    if wl and len(wl) > 1:
        from .mitsuba import ExportError

        raise ExportError(f"PARAMS_JSON {path!r}: the fit's bands are wavelengths ({', '.join(f'{w:g}' for w in wl)} "
                          "nm); Mitsuba's RGB properties need R, G, B bands (refit on an RGB table)")


def run(args) -> int:
    kind = _check_options(args)
    from . import mitsuba as mx

    rec = mx.read_params_json(args.params_json)
    _check_bands(rec, args.params_json)
    model, params = mx.from_params_json(args.params_json)
    diffs = mx.differences(model, params)
    d = mx.to_mitsuba(model, params, approximate=args.approximate)
    source = f"{model.name} fitted in {os.path.abspath(args.params_json)}"
    if kind == "xml":
        comment = f"appearance-jax export: {source}" + ("; approximated: " + "; ".join(diffs) if diffs else "")
        text = mx.dict_to_xml(d, id=args.id, comment=comment)
    else:
        text = json.dumps(d, indent=2) + "\n"
    if rec.get("converged") is False:
        print(f"appearance-jax export: warning: the fit in {args.params_json} did not converge", file=sys.stderr)
    for line in diffs:
        print(f"appearance-jax export: approximated: {line}", file=sys.stderr)
    if args.out is None:
        sys.stdout.write(text)
        return 0
    with open(args.out, "w", encoding="utf-8") as fh:
        fh.write(text)
    what = d["type"] if d["type"] != "blendbsdf" else "blendbsdf of " + model.name.replace("+", ", ")
    print(f"wrote {args.out} (Mitsuba 3 {'XML' if kind == 'xml' else 'load_dict JSON'}: {model.name} -> {what}"
          f"{', approximated' if diffs else ''})")
    return 0
