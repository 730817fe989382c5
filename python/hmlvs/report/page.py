"""The pieces every HTML report shares: the page and its style, figures as inline PNGs, and the
verdict with its uncertainty map (shown first in the reports of both models)."""

from __future__ import annotations

import base64
import html
import io
from typing import Any

import numpy as np


def png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


_STYLE = """
body { font-family: sans-serif; margin: 2em; color: #222; max-width: 1100px; }
table { border-collapse: collapse; margin: 1em 0; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: right; font-size: 13px; }
td:nth-child(3) { text-align: left; }
th { background: #eee; }
.summary td { text-align: left; }
li.warn { color: #a40; font-weight: bold; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; }
img { max-width: 520px; border: 1px solid #ddd; }
"""


def page(title: str, body: str) -> str:
    """A whole self-contained HTML page around ``body``."""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style></head><body>\n"
            f"{body}</body></html>\n")


def figures_html(figs: dict[str, str], captions: dict[str, str]) -> str:
    return "".join(f'<figure><img alt="{captions[k]}" src="{v}"><figcaption>{captions[k]}'
                   f"</figcaption></figure>" for k, v in figs.items())


#: the uncertainty map's cells over the image (columns, rows)
_MAP_GRID = (8, 6)


def _uncertainty_map(verdict: Any) -> str:
    """The predicted 3D uncertainty over the image, as a table of cells: the 95th
    percentile (mm) of the stripe pixels' predicted standard deviations in each cell,
    shaded by it; "-" where the calibration saw no stripe (measurements there rest on
    extrapolation)."""
    pts = getattr(verdict, "map_points", None)
    size = getattr(verdict, "image_size", None)
    if pts is None or len(pts) == 0 or size is None:
        return ""
    gx, gy = _MAP_GRID
    w, h = size
    i = np.clip((pts[:, 0] / w * gx).astype(int), 0, gx - 1)
    j = np.clip((pts[:, 1] / h * gy).astype(int), 0, gy - 1)
    top = float(np.percentile(pts[:, 2], 95)) or 1.0
    rows = []
    for r in range(gy):
        cells = []
        for c in range(gx):
            sel = pts[(i == c) & (j == r), 2]
            if sel.size == 0:
                cells.append('<td style="background:#eee">-</td>')
                continue
            q = float(np.percentile(sel, 95))
            x = min(q / top, 1.0)
            colour = f"rgb({int(255 * x)},{int(200 * (1 - x) + 55)},80)"
            cells.append(f'<td style="background:{colour}">{q:.3f}</td>')
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return ("<p>Predicted 3D uncertainty over the image (95th percentile in mm of the "
            "stripe points seen in each part of the image; '-': no stripe seen there, "
            f"measurements there rest on extrapolation):</p><table class=\"map\">"
            f"{''.join(rows)}</table>")


def verdict_html(verdict: Any) -> str:
    """The verdict, first in a report, in words a technician reads: whether to trust the
    calibration, what that means for measuring, why (the likely mistake first); then the
    predicted 3D uncertainty and its map over the image; then every check with its limit
    and the reason for that limit."""
    if verdict is None:
        return ""
    advice = f"<p>{html.escape(verdict.advice())}</p>"
    if verdict.trustworthy:
        head = ('<p class="verdict ok"><b>Verdict: this calibration can be trusted.</b> '
                f'Every check passed.</p>{advice}')
    else:
        items = "".join(f"<li>{html.escape(r)}</li>" for r in verdict.reasons)
        head = ('<p class="verdict warn"><b>Verdict: this calibration is NOT to be trusted.'
                f'</b></p>{advice}<p>Why:</p><ul class="warn">{items}</ul>')
    ms = verdict.map_sigma_mm
    unc = ("" if ms is None else
           f"<p>Predicted 3D uncertainty of measured points over the laser line's image "
           f"footprint: {ms['rms']:.3f} mm RMS, {ms['p95']:.3f} mm at the 95th percentile.</p>")
    cv = getattr(verdict, "cross_validation_mm", None)
    if cv is not None:
        unc += (f"<p>Calibrated on two halves of the views, the maps differ by "
                f"{cv['rms']:.3f} mm RMS, {cv['p95']:.3f} mm at the 95th percentile.</p>")
    rows = "".join(
        f"<tr><td>{'ok' if c.ok else '<b>FAIL</b>'}</td><td>{html.escape(c.name)}</td>"
        f"<td>{c.value:.4g} {html.escape(c.unit)}</td><td>{'&le;' if c.kind == 'max' else '&ge;'}"
        f" {c.limit:.4g} {html.escape(c.unit)}</td><td>{html.escape(c.why)}</td></tr>"
        for c in verdict.checks)
    unc += _uncertainty_map(verdict)
    return (f"<h2>Verdict</h2>{head}{unc}<h3>The checks</h3><table><tr><th></th><th>check</th>"
            f"<th>value</th><th>limit</th><th>why this limit</th></tr>{rows}</table>")
