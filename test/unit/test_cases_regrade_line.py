"""`cases regrade` prints, for a nodular case, where its lesions stand out from the normal
background (the background grading), and for a smooth case their contrast against the breast."""
from __future__ import annotations

from haptic_anfis import cli
from haptic_anfis.cases import library
from haptic_anfis.cases.background import regrade_background
from haptic_anfis.commands import cases as cases_cmd
from haptic_anfis.commands.cases import regrade_line

NODULAR = 'nod_s_fatty_idc10_d10'   # a shipped nodular case whose lesion never stands out


def test_regrade_prints_a_nodular_lesion_by_the_background_grading(monkeypatch, capsys):
    g = library().get(NODULAR).grading()
    bg = g['background']['lesions'][0]
    smooth = g['lesions'][0]
    assert not bg['stands_out'] and bg['reason'] != smooth['reason']
    # the store holds the FE points; the line is made from the grading regrade_case returns
    monkeypatch.setattr(cases_cmd, 'regrade_case', lambda case, **kw: g)
    assert cli.main(['cases', 'regrade', NODULAR]) == 0
    out = capsys.readouterr().out
    assert out == f'{NODULAR}: level {g["level"]}: {bg["lesion"]} {bg["reason"]}\n'
    assert 'below what this device renders' not in out


def test_a_nodular_lesion_that_stands_out_is_printed_with_its_margin_over_the_normal_regions():
    g = library().get(NODULAR).grading()
    low = regrade_background(g['background'], 1.0)   # a threshold its lesion stands out at
    e = low['lesions'][0]
    assert e['stands_out']
    line = regrade_line(NODULAR, {**g, 'level': low['level'], 'background': low})
    assert line == (f'{NODULAR}: level {low["level"]}: {e["lesion"]} d{e["difficulty"]} at '
                    f'{e["found_level"]} ({e["found_depth_m"] * 1e3:g} mm, '
                    f'{e["margin_pct"]:+.1f} % over the firmest normal region)')


def test_a_smooth_case_is_printed_by_its_contrast_against_the_breast():
    case = next(c for c in library().cases() if c.grading() is not None
                and 'background' not in c.grading()
                and any(e['palpable'] for e in c.grading()['lesions']))
    g = case.grading()
    e = next(e for e in g['lesions'] if e['palpable'])
    line = regrade_line(case.name, g)
    assert (f'{e["lesion"]} d{e["difficulty"]} at {e["found_level"]} '
            f'({e["found_depth_m"] * 1e3:g} mm, {e["contrast_pct"]:+.1f} %)') in line
    assert 'normal region' not in line
