"""Text a user typed (a trainee id, an error that repeats it, a case or lesion name from a file)
shown in viser's Markdown panels as text, never as markup (no ROS).

viser renders Markdown with raw HTML allowed: ``<img src=x onerror=...>`` in a panel's content
becomes an element in every open page. :func:`md` escapes HTML's characters as entities (the
renderer shows them as the characters) and Markdown's punctuation with backslashes (no link,
image, emphasis or table cell made from the text).
"""
from __future__ import annotations

__all__ = ['md']

#: the Markdown punctuation that could make markup of a text within a line (code, emphasis,
#: links and images, table cells, strikethrough, headings)
_MD = set('\\`*_[]()!|~#')


def md(text: object) -> str:
    """``text`` (str() of it) as Markdown that renders exactly as the characters given, on one
    line (line breaks become spaces)."""
    out = []
    for c in str(text):
        if c in '<>&"\'':
            out.append(f'&#{ord(c)};')   # an entity: the renderer shows the character
        elif c in _MD:
            out.append('\\' + c)
        elif c in '\r\n':
            out.append(' ')
        else:
            out.append(c)
    return ''.join(out)
