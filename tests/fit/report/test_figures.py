"""The report's figures read: log tone mapping, reciprocity fill of the maps, slices in frame."""

import dataclasses

import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.fit.report.figures import maps_figure, slices_figure
from appearance_jax.fit.report.geometry import PlanePoints, reciprocity_fill
from appearance_jax.fit.report.tonemap import V_HI, V_LO, LogTone, log_tone, symmetric_limit
from appearance_jax.fit.solve import fit
from appearance_jax.fit.tables.table import Table

DIFFUSE = 0.1 / np.pi  # 1/sr
PEAK = 1e3 * DIFFUSE


def _glossy(ti, to):
    """f [1/sr]: a diffuse floor and a narrow mirror lobe 1000 x brighter (RGB)."""
    lobe = np.exp(-((to - ti) / np.deg2rad(2.0)) ** 2)
    return (DIFFUSE + PEAK * lobe)[:, None] * np.array([1.0, 0.8, 0.6])


def _table(drop=(), zero=()):
    ti, to = np.meshgrid(np.deg2rad([0.0, 20.0, 40.0, 60.0]), np.deg2rad(np.arange(-80.0, 81.0, 10.0)), indexing="ij")
    ti, to = ti.ravel(), to.ravel()
    v = _glossy(ti, to)
    key = list(zip(np.round(np.rad2deg(ti)), np.round(np.rad2deg(to))))
    for k in zero:
        v[key.index(k)] = 0.0
    keep = np.array([k not in drop for k in key])
    return Table.in_plane(ti[keep], to[keep], v[keep], mask=np.ones_like(v[keep], bool), source="synthetic glossy")


@pytest.fixture(scope="module")
def base_fit():
    return fit("lambert", _table())


def _on(result, table):
    """``result`` drawn on ``table`` (same params): the figures' job is drawing, not fitting."""
    wi, wo = table.directions()
    f = np.asarray(registry.get("lambert").eval(result.params, wi, wo), np.float64)
    return dataclasses.replace(result, table=table, fitted=np.array(np.broadcast_to(f, table.values.shape)),
                               n_valid=int(table.mask.sum()), masked=dict(table.masked))


# ------------------------------------------------------------------------------ tone mapping


def test_tone_shows_peak_and_a_1000x_smaller_diffuse_value():
    rgb = np.array([[1.0, 1.0, 1.0], [1e-3, 1e-3, 1e-3], [2e-3, 1e-3, 5e-4]])
    tone = log_tone(rgb)
    out = tone(rgb)
    assert tone.hi == pytest.approx(1.0) and tone.lo <= 1e-3
    assert np.all(out.max(axis=1) > 0.1)  # non-black
    assert np.all(out < 0.99)  # non-saturated
    assert np.abs(out[0] - out[1]).max() > 0.2  # distinct
    # equal steps per decade: the brightness (sRGB value) is linear in log10 luminance
    v = tone(np.array([[1.0] * 3, [0.1] * 3, [0.01] * 3])).max(axis=1)
    np.testing.assert_allclose(v[0] - v[1], v[1] - v[2], rtol=1e-9)
    assert v[0] == pytest.approx(V_HI)
    assert tone(np.zeros((1, 3)))[0].max() == pytest.approx(V_LO)  # zero: darkest level, not black
    assert np.isnan(tone(np.full((1, 3), np.nan))).all()  # no value stays NaN (drawn as "no sample")


def test_tone_keeps_hue_and_checks_its_range():
    out = LogTone(1e-3, 1.0)(np.array([[0.5, 0.1, 0.0]]))[0]
    assert out[0] > out[1] > out[2] == 0.0
    with pytest.raises(ValueError, match="lo"):
        LogTone(1.0, 1.0)
    with pytest.raises(ValueError, match="max_decades"):
        log_tone(np.ones((2, 3)), max_decades=0.5)
    assert log_tone(np.array([[1.0, 1.0, 1.0], [1e-12, 1e-12, 1e-12]])).decades == pytest.approx(6.0)


def test_symmetric_limit():
    assert symmetric_limit(np.array([0.03, -0.04, np.nan])) == 0.05
    assert symmetric_limit(np.linspace(-0.3, 0.3, 101)) == 0.5
    assert symmetric_limit(np.array([50.0])) == 2.0


def _pixel(fig, ax, x, y):
    fig.canvas.draw()
    buf = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float) / 255.0
    px, py = ax.transData.transform((x, y))
    return buf[int(round(buf.shape[0] - py)), int(round(px))]


def test_maps_show_peak_and_diffuse_on_one_scale(base_fit):
    import matplotlib.pyplot as plt

    fig, desc = maps_figure(_on(base_fit, _table()), model="lambert")
    try:
        meas = fig.axes[0]
        peak, diffuse = _pixel(fig, meas, 20.0, 20.0), _pixel(fig, meas, -60.0, 20.0)
        assert peak.max() < 0.99 and diffuse.max() > 0.1, (peak, diffuse)
        assert peak.max() - diffuse.max() > 0.3
        assert "log10 luminance" in desc and "decades" in desc
        titles = " ".join(ax.get_title() for ax in fig.axes) + " ".join(ax.get_ylabel() for ax in fig.axes)
        assert "log" in titles and "1/sr" in titles  # the mapping and its units are stated
        assert any(line.get_gid() == "mirror" for line in meas.lines)
    finally:
        plt.close(fig)


# ------------------------------------------------------------------------------ reciprocity fill


def _points(keys, regular):
    ti, to = np.array(keys, float).T
    v = (1.0 + ti[:, None] + 100.0 * to[:, None]) * np.ones((1, 3))  # unique per point
    return PlanePoints(ti, to, v, 2 * v, len(keys), regular, True)


def test_reciprocity_fill_on_a_grid():
    grid = [(a, b) for a in (0.0, 20.0, 40.0) for b in (-40.0, -20.0, 0.0, 20.0, 40.0)]
    missing = {(40.0, 20.0), (20.0, 40.0),  # each other's partner: neither can be filled
               (40.0, -20.0), (0.0, 40.0), (20.0, 0.0)}  # partners (20, -40), (40, 0), (0, +-20) measured
    p = _points([k for k in grid if k not in missing], True)
    q = reciprocity_fill(p)
    got = {(a, b): i for i, (a, b) in enumerate(zip(q.ti, q.to)) if q.filled[i]}
    assert set(got) == {(40.0, -20.0), (0.0, 40.0), (20.0, 0.0)}
    src = {(a, b): i for i, (a, b) in enumerate(zip(p.ti, p.to))}
    for (a, b), i in got.items():
        partners = [src[(abs(b), np.sign(b) * a)]] if b != 0 else [src[(0.0, a)], src[(0.0, -a)]]
        assert any(np.array_equal(q.meas[i], p.meas[j]) and np.array_equal(q.fit[i], p.fit[j]) for j in partners)
    assert not q.filled[: p.ti.size].any() and q.ti.size == p.ti.size + 3


def test_reciprocity_fill_replaces_unmeasured_cells_only():
    p = _points([(0.0, 20.0), (20.0, 0.0), (20.0, 20.0), (0.0, 0.0)], True)
    p.meas[0] = np.nan  # (0, 20) not measured; its partner (20, 0) is
    q = reciprocity_fill(p)
    assert q.ti.size == 4 and q.filled.sum() == 1
    i = np.flatnonzero(q.filled)[0]
    assert (q.ti[i], q.to[i]) == (0.0, 20.0) and np.isfinite(q.meas[i]).all()


def test_reciprocity_fill_of_scattered_points_fills_the_missing_wedge():
    # one half of the forward side measured (theta_o <= theta_i) plus the whole retro side, like a MERL table
    keys = [(a, b) for a in np.arange(0.0, 81.0, 5.0) for b in np.arange(-80.0, 81.0, 5.0) if b <= a]
    q = reciprocity_fill(_points(keys, False))
    filled = set(zip(q.ti[q.filled], q.to[q.filled]))
    assert filled == {(b, a) for a, b in keys if 0 <= b < a}


def test_maps_hatch_the_filled_cells(base_fit):
    import matplotlib.pyplot as plt

    t = _table(drop={(60.0, 40.0), (40.0, -20.0)})  # partners (40, 60) and (20, -40) are measured
    fig, desc = maps_figure(_on(base_fit, t), model="lambert")
    try:
        hatched = [c for c in fig.axes[0].collections if c.get_gid() == "reciprocity_fill"]
        assert len(hatched) == 1 and len(hatched[0].get_paths()) == 2 and hatched[0].get_hatch()
        assert "2 points filled by reciprocity" in desc
    finally:
        plt.close(fig)


# ------------------------------------------------------------------------------ slices


def test_slices_keep_every_point_in_frame_and_mark_the_mirror(base_fit):
    import matplotlib.pyplot as plt

    t = _table(zero={(20.0, -80.0)})  # a zero: finite, but below any log axis
    fig, desc = slices_figure(_on(base_fit, t), model="lambert")
    try:
        axes = [ax for ax in fig.axes if ax.get_visible() and ax.get_title()]
        assert len(axes) == 4
        n_drawn = 0
        for ax in axes:
            ti = float(ax.get_title().split("=")[1].strip(" °"))
            y0, y1 = ax.get_ylim()
            x0, x1 = ax.get_xlim()
            assert ax.get_yscale() == "log" and "1/sr" in ax.get_ylabel() and "deg" in ax.get_xlabel()
            for line in ax.lines:
                if line.get_linestyle() == "None":  # measured markers
                    x, y = np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
                    assert np.all((y > y0) & (y < y1) & (x >= x0) & (x <= x1)), (ti, line.get_label())
                    n_drawn += x.size
            mirror = [line for line in ax.lines if line.get_gid() == "mirror"]
            assert len(mirror) == 1 and np.allclose(mirror[0].get_xdata(), ti)
        assert n_drawn == 3 * 4 * 17  # every finite value of the 4 slices, channel by channel
        assert "drawn at the floor" in desc  # the zero
    finally:
        plt.close(fig)
