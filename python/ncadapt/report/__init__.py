"""HTML reports: one self-contained file (figures embedded as PNG), readable offline and easy to
send by mail. Figures are drawn with matplotlib (Agg backend, no display needed)."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from .._io import atomic_write

CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2rem auto;max-width:1100px;color:#222;padding:0 1rem}
h1{font-size:1.6rem;margin-bottom:.2rem} h2{font-size:1.2rem;margin-top:2rem;border-bottom:1px solid #ddd;padding-bottom:.2rem}
.sub{color:#666;margin-top:0} table{border-collapse:collapse;margin:.5rem 0} td,th{padding:.25rem .8rem;border-bottom:1px solid #eee;text-align:right}
th{text-align:left;font-weight:600} td:first-child{text-align:left} .verdict{font-size:1.1rem;padding:.6rem 1rem;border-radius:6px;display:inline-block}
.yes{background:#fde8e8;color:#8a1c1c} .no{background:#e6f4ea;color:#1e5c2f} .big{font-size:1.4rem;font-weight:600}
figure{margin:1rem 0} figcaption{color:#555;font-size:.9rem} img{max-width:100%}
.cards{display:flex;gap:1rem;flex-wrap:wrap} .card{border:1px solid #ddd;border-radius:6px;padding:.8rem 1.2rem;min-width:200px}
"""


def pyplot():
    """matplotlib.pyplot on the Agg backend (reports are drawn without a display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure_png(fig) -> str:
    """A matplotlib figure as an <img> tag with embedded PNG."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return f'<img alt="figure" src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}">'


def table(rows, header=None) -> str:
    out = ["<table>"]
    if header:
        out.append("<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>")
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "".join(out)


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return f"{v:.4g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.3e}"
    return str(v)


def page(title: str, subtitle: str, sections: list[tuple[str, str]]) -> str:
    body = "".join(f"<h2>{html.escape(h)}</h2>{content}" for h, content in sections)
    return (
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{CSS}</style></head><body><h1>{html.escape(title)}</h1><p class='sub'>{html.escape(subtitle)}</p>"
        f"{body}</body></html>"
    )


def write(path, text: str) -> Path:
    return atomic_write(path, text.encode("utf-8"))
