"""The trainee's page's HTML pieces (no ROS, no viser): the colour legend, the pressure gauge with
its band ticks, the cue banner. Colours from :mod:`haptic_anfis.palette` (the meanings of the
exam's report.png); no text here comes from a user, so nothing needs escaping.

The gauge's scale is the depth under the probe from 0 to 1.5 x the deep threshold (as
:func:`~haptic_anfis.view.gauge.gauge`'s ``percent``), painted with the same continuous pressure
colours as the dent on the skin, with a tick at each level's threshold.
"""
from __future__ import annotations

from ..exam.config import LEVELS
from ..palette import LEVEL, NOT_PRESSED, OUTCOME, REGION, rgb255
from .scene import LESION_RGB, MARK_RGB, NORMAL_RGB, OUTSIDE_RGB

__all__ = ['banner_html', 'gauge_html', 'legend_html']

#: the banner's background per cue kind: right (bluish green), to fix (orange), the exam over
#: (grey), Okabe-Ito
BANNER_BG = {'good': OUTCOME['pass'], 'fix': OUTCOME['retry'], 'over': OUTCOME['void']}
#: the banner's sign per cue kind
SIGN = {'good': '\u2714 ', 'fix': '\u26a0 ', 'over': ''}


def _hex(rgb) -> str:
    return '#%02x%02x%02x' % tuple(int(c) for c in rgb)


def _scale(thresholds) -> tuple[float, str]:
    """(full scale [m], the CSS gradient of the pressure colours over it)."""
    full = 1.5 * thresholds[-1]
    stops = [f'{NOT_PRESSED} 0%'] + [f'{LEVEL[k]} {100 * t / full:.1f}%'
                                     for k, t in zip(LEVELS, thresholds)]
    return full, f"linear-gradient(to right, {', '.join(stops)}, {LEVEL['deep']} 100%)"


def _ticks(thresholds, full: float) -> str:
    return ''.join(
        f'<div style="position:absolute;left:{100 * t / full:.1f}%;top:0;height:100%;'
        f'border-left:2px solid #000"></div>'
        f'<div style="position:absolute;left:{100 * t / full:.1f}%;top:100%;'
        f'transform:translateX(-50%);font-size:0.8em;white-space:nowrap">'
        f'{k} {t * 1e3:.0f}</div>' for k, t in zip(LEVELS, thresholds))


def gauge_html(thresholds, depth_m: float | None) -> str:
    """The pressure bar: the colour scale with a tick and label per level threshold [m] and a
    black marker at ``depth_m`` [m] (None: no marker, the probe is off the skin)."""
    full, grad = _scale(thresholds)
    mark = '' if depth_m is None else (
        f'<div style="position:absolute;left:{min(100.0, 100 * depth_m / full):.1f}%;top:-4px;'
        f'height:calc(100% + 8px);width:6px;transform:translateX(-50%);background:#000;'
        f'border:1px solid #fff"></div>')
    return (f'<div style="margin:4px 10px 18px 10px"><div style="position:relative;height:18px;'
            f'background:{grad};border:1px solid {REGION}">{_ticks(thresholds, full)}{mark}'
            f'</div><div style="font-size:0.8em;text-align:right;margin-top:16px">depth under '
            f'the probe [mm]</div></div>')


def legend_html(debrief: bool = False, background: bool = False) -> str:
    """What the skin's colours mean: not yet palpated inside the outline, the deepest level
    reached, outside the region, the outline; live the trainee's marks, in the ``debrief`` the
    lesions revealed and the marks scored, and with a nodular ``background`` its normal lobules
    and ribs (and those that stand out as much as a lesion would)."""
    rows = [(NOT_PRESSED, 'not palpated' if debrief else 'not yet palpated'),
            (LEVEL['light'], 'palpated light'), (LEVEL['medium'], 'palpated medium'),
            (LEVEL['deep'], 'palpated deep'), (_hex(OUTSIDE_RGB), 'outside the region'),
            (REGION, 'region to examine')]
    if debrief:
        rows += [(_hex(LESION_RGB['hit']), 'lump found / mark on it'),
                 (_hex(LESION_RGB['missed']), 'lump missed'),
                 (_hex(LESION_RGB['below device']), 'lump not renderable'),
                 (_hex(MARK_RGB['false']), 'mark on no lump')]
        if background:
            rows += [(_hex(NORMAL_RGB['normal']), 'normal lobule / rib (no lump)'),
                     (_hex(NORMAL_RGB['confounder']), 'normal, but stands out like a lump')]
    else:
        rows.append((_hex(MARK_RGB['live']), 'your marks'))
    return ('<div style="font-size:0.85em;margin:2px 10px;display:grid;'
            'grid-template-columns:1fr 1fr;column-gap:8px">') + ''.join(
        f'<div><span style="display:inline-block;width:14px;height:14px;background:{c};'
        f'border:1px solid #666;vertical-align:middle;margin-right:6px"></span>{t}</div>'
        for c, t in rows) + '</div>'


def banner_html(cue: str, kind: str) -> str:
    """The cue as a banner the trainee sees while palpating ('' without a cue)."""
    if not cue:
        return ''
    bg = BANNER_BG.get(kind, OUTCOME['retry'])
    r, g, b = rgb255(bg)
    fg = '#000' if 0.299 * r + 0.587 * g + 0.114 * b > 140 else '#fff'
    sign = SIGN.get(kind, SIGN['fix'])
    return (f'<div style="font-size:1.5em;font-weight:bold;padding:10px 12px;margin:4px 8px;'
            f'border-radius:6px;background:{bg};color:{fg}">{sign}{cue}</div>')
