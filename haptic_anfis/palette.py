"""One picture language: what each colour means, for every figure and page (no ROS, no numpy).

The same meaning has the same colour in the exam's report.png (:mod:`haptic_anfis.exam.figure`),
the trainee's progress figure (:mod:`haptic_anfis.record.figure`) and the browser page
(:mod:`haptic_anfis.view` can take its colours from here). Two families, both safe for the
common colour-vision deficiencies:

- **pressure** (how deep the skin was pressed: coverage per level, the depth along the path):
  ColorBrewer's sequential YlOrRd (Brewer & Harrower, colorbrewer2.org, marked colour-blind
  safe: its lightness falls monotonically, so the order reads in grey too): pale yellow light,
  orange medium, dark red deep; never pressed is a neutral grey (the skin tone on the page).
  Red therefore always means *pressed deep*, never "missing".
- **findings and outcomes** (lesions, marks, pass / retry): the Okabe-Ito palette (Okabe & Ito
  2002, "Color Universal Design"; Wong, Nature Methods 8:441, 2011), distinct under
  protanopia, deuteranopia and tritanopia: bluish green found / hit / pass, reddish purple
  missed, sky blue a repeated mark, black a false mark, grey not palpable, orange retry;
  after the exam the breast's normal background (its lobules and ribs): blue, and vermillion
  for normal tissue that stands out as much as a lesion would (a confounder).

Colours are ``#rrggbb`` strings; :func:`rgb255` gives (r, g, b) 0-255 for a page or a mesh.
"""
from __future__ import annotations

__all__ = ['FINDING', 'LEVEL', 'LEVEL_LABEL', 'MARK', 'NORMAL', 'NOT_PRESSED', 'OUTCOME',
           'PRESSURE_CMAP', 'REGION', 'SENSITIVITY', 'SKIN', 'TIME', 'rgb255']

#: never pressed to the light level (figures; lighter than light, so less pressed is always
#: lighter, in grey too); the page shows the skin instead
NOT_PRESSED = '#f2f2f2'
#: the outline of the region to examine
REGION = '#525252'
#: untouched skin on the page
SKIN = '#ecc4b2'
#: the deepest level pressed, by level name (YlOrRd: lightness falls with depth)
LEVEL = {'light': '#fed976', 'medium': '#fd8d3c', 'deep': '#bd0026'}
#: the legend's words for the coverage colours, in order
LEVEL_LABEL = {'none': 'not pressed', 'light': 'light', 'medium': 'medium', 'deep': 'deep'}
#: a continuous pressure (depth / force) map: matplotlib's name of the same sequential scale
PRESSURE_CMAP = 'YlOrRd'
#: lesions revealed after the exam (Okabe-Ito)
FINDING = {'found': '#009e73', 'missed': '#cc79a7', 'not palpable': '#999999'}
#: the trainee's marks: on a lesion, again on a lesion already found, on no lesion, on a
#: lesion the FE says cannot be felt (neither hit nor false)
MARK = {'hit': '#009e73', 'repeat': '#56b4e9', 'false': '#000000', 'not_palpable': '#999999'}
#: the normal background revealed after the exam (Okabe-Ito blue and vermillion): a normal
#: lobule or rib, and one whose bump reaches the palpability threshold (it stands out as much as
#: a lesion would: a confounder)
NORMAL = {'normal': '#0072b2', 'confounder': '#d55e00'}
#: a session's verdict; void: the haptic loop fell behind, it does not count
OUTCOME = {'pass': '#009e73', 'retry': '#e69f00', 'void': '#999999'}
#: the share of palpable lesions found (progress figure)
SENSITIVITY = '#0072b2'
#: session time and time in contact (progress figure)
TIME = {'session': '#bdbdbd', 'contact': '#525252'}


def rgb255(colour: str) -> tuple[int, int, int]:
    """``'#rrggbb'`` as (r, g, b), each 0-255.

    Raises:
        ValueError: not a ``#rrggbb`` string (naming it).
    """
    if not (isinstance(colour, str) and len(colour) == 7 and colour[0] == '#'):
        raise ValueError(f'colour {colour!r}: expected #rrggbb')
    try:
        return tuple(int(colour[k:k + 2], 16) for k in (1, 3, 5))  # type: ignore[return-value]
    except ValueError:
        raise ValueError(f'colour {colour!r}: expected #rrggbb') from None
