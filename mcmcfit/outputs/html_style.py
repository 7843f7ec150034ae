"""The CSS rules shared by the HTML reports (per fit and per batch).

Both pages use the same font, headings and right-aligned tables with
left-aligned ``l`` cells; each report sets its own page width, heading
spacing, table font size and cell padding, and adds the rules of its own
elements (figures, status rows).

This module imports nothing from the project.
"""

from __future__ import annotations

__all__ = ["base_css"]


def base_css(*, max_width: str, h2_margin_top: str, table_font_size: str,
             cell_padding: str) -> str:
    """Return the page, heading and table rules of a report, one rule line each.

    Parameters
    ----------
    max_width : str
        CSS length of the page's maximum width (``"1100px"``).
    h2_margin_top : str
        CSS length above each ``h2`` heading (``"1.6em"``).
    table_font_size : str
        CSS font size of tables (``"0.85em"``).
    cell_padding : str
        CSS padding of table cells (``"2px 8px"``).

    Returns
    -------
    str
        Five lines of CSS, each ending in a newline.
    """
    return (
        "body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; "
        f"max-width: {max_width}; }}\n"
        f"h1 {{ font-size: 1.4em; }} h2 {{ font-size: 1.15em; margin-top: {h2_margin_top}; "
        "border-bottom: 1px solid #ccc; }\n"
        f"table {{ border-collapse: collapse; font-size: {table_font_size}; margin: 0.5em 0; }}\n"
        f"td, th {{ border: 1px solid #ccc; padding: {cell_padding}; text-align: right; }}\n"
        "th { background: #f2f2f2; } td.l, th.l { text-align: left; }\n"
    )
