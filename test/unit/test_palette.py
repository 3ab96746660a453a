"""One picture language: the palette's colours, and the figures drawing what is there."""
from __future__ import annotations

import matplotlib
import pytest

from haptic_anfis import palette
from haptic_anfis.record.figure import save_progress_figure

matplotlib.use('Agg')


def luminance(colour: str) -> float:
    """Relative luminance (WCAG 2: sRGB linearised, Rec. 709 weights), 0-1."""
    lin = [(c / 255) / 12.92 if c / 255 <= 0.04045 else ((c / 255 + 0.055) / 1.055) ** 2.4
           for c in palette.rgb255(colour)]
    return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]


def test_pressure_colours_darken_with_depth_so_the_order_reads_without_hue():
    order = [palette.LEVEL[k] for k in ('light', 'medium', 'deep')]
    lum = [luminance(c) for c in order]
    assert lum == sorted(lum, reverse=True) and lum[0] - lum[-1] > 0.5
    assert luminance(palette.NOT_PRESSED) > lum[0] + 0.1   # not pressed: lighter still


def test_findings_keep_their_meaning_everywhere():
    assert palette.FINDING['found'] == palette.MARK['hit'] == palette.OUTCOME['pass']
    assert palette.FINDING['not palpable'] == palette.OUTCOME['void']
    assert len(set(palette.FINDING.values())) == 3
    assert palette.rgb255(palette.SKIN) == (236, 196, 178)   # the page's untouched skin
    with pytest.raises(ValueError, match="colour 'red': expected #rrggbb"):
        palette.rgb255('red')


def test_progress_figure_draws_no_sensitivity_for_a_session_without_a_lump(tmp_path,
                                                                          monkeypatch):
    import matplotlib.pyplot as plt
    figs = []
    monkeypatch.setattr(plt, 'close', figs.append)

    def s(k, sens, verdict='pass', void=None):
        return {'coverage_pct': {'light': 99.0, 'medium': 95.0, 'deep': 91.0},
                'sensitivity': sens, 'false_marks': 0, 'duration_s': 100.0, 'contact_s': 80.0,
                'case_level': 1, 'verdict': verdict, 'void': void}
    sessions = [s(1, 1.0), s(2, None), s(3, 0.0, 'retry'), s(4, 1.0, void='loop behind')]
    save_progress_figure('t', sessions, tmp_path / 'p.png', None, 90.0)
    (fig,) = figs
    ax = fig.axes[1]
    ys = [y for line in ax.get_lines() for y in line.get_ydata()]
    assert sorted(ys) == [0.0, 100.0, 100.0] and 50 not in ys   # nothing invented for session 2
    for a in fig.axes:   # every panel has its legend
        assert a.get_legend() is not None and a.get_legend().get_texts()
    dots = [line.get_markerfacecolor() for line in fig.axes[4].get_lines()
            if line.get_marker() == 'o' and len(line.get_xdata()) == 1]
    want = [palette.OUTCOME[k] for k in ('pass', 'pass', 'retry', 'void')]
    assert [matplotlib.colors.to_hex(c) for c in dots] == want
    assert (tmp_path / 'p.png').stat().st_size > 10_000
