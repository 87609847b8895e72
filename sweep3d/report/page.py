"""The page around the panels: template environment, inlined assets, Content-Security-Policy.

plotly.js (see :func:`plotly_js`) and the report's own scripts (``static/*.js``) are inlined, each in its own
``<script>`` element whose SHA-256 the CSP lists; data travels as JSON in
``<script type="application/json">`` blocks, which browsers never run. The CSP allows nothing
else (no network, no other script), so a name from a spec or a model cannot become code.
"""

from __future__ import annotations

import base64
import hashlib
import os
import sys
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import jinja2
from markupsafe import Markup

#: The report's scripts, run in this order after plotly.js.
SCRIPTS = ("report.js", "explorer.js")
STYLESHEET = "report.css"
#: plotly.js's smaller "cartesian" bundle, installed at set-up time from the npm registry
#: (``plotly.js-cartesian-dist-min``, MIT) by scripts/setup.sh; not part of this repository.
PLOTLY_CARTESIAN = Path(sys.prefix) / "share" / "sweep3d" / "plotly-cartesian.min.js"

_JSON_ESCAPES = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026", "\u2028": "\\u2028", "\u2029": "\\u2029"}


def render_page(context: dict[str, Any]) -> str:
    """The HTML of the report page for ``context`` (see :func:`sweep3d.report.build_context`)."""
    scripts = [plotly_js(), *(static_text(name) for name in SCRIPTS)]
    csp = "; ".join([
        "default-src 'none'",
        "script-src " + " ".join(csp_hash(s) for s in scripts),
        "style-src 'unsafe-inline'",
        "img-src data: blob:",
        "font-src data:",
    ])
    return environment().get_template("report.html.j2").render(
        **context, scripts=[Markup(s) for s in scripts], stylesheet=Markup(static_text(STYLESHEET)), csp=csp
    )


def script_json(text: str) -> Markup:
    """JSON text made safe inside ``<script>``: ``<``, ``>`` and ``&`` become ``\\u003c`` etc.

    A name such as ``</script><script>…`` then cannot end the element early, and JSON.parse
    reads the same value back.
    """
    for char, escape in _JSON_ESCAPES.items():
        text = text.replace(char, escape)
    return Markup(text)


def csp_hash(script: str) -> str:
    """The CSP source expression (``'sha256-…'``) allowing the inline script ``script``."""
    digest = hashlib.sha256(script.encode("utf-8")).digest()
    return "'sha256-" + base64.b64encode(digest).decode("ascii") + "'"


@lru_cache(maxsize=None)
def static_text(name: str) -> str:
    """A file of ``sweep3d/report/static``, with line ends as the browser will see them."""
    return _browser_text(resources.files("sweep3d.report").joinpath("static", name).read_text(encoding="utf-8"))


@lru_cache(maxsize=1)
def plotly_js() -> str:
    """plotly.js for the page: the cartesian bundle when it is installed and is the version
    plotly.py writes figures for, else the full bundle inside the plotly package.

    The cartesian bundle has every trace type the report draws and starts in about half the
    time of the full one (``SWEEP3D_PLOTLY_JS`` may point at another copy).
    """
    from plotly.offline import get_plotlyjs, get_plotlyjs_version

    path = Path(os.environ.get("SWEEP3D_PLOTLY_JS", PLOTLY_CARTESIAN))
    if path.is_file():
        bundled = _browser_text(path.read_text(encoding="utf-8"))
        if f"v{get_plotlyjs_version()}\n" in bundled[:200]:
            return bundled
    return _browser_text(get_plotlyjs())


@lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    """The Jinja environment: autoescaping, strict about undefined names."""
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("sweep3d.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["script_json"] = script_json
    return env


def _browser_text(text: str) -> str:
    # The HTML parser turns CR LF into LF; hash and emit the text the browser will see.
    return text.replace("\r\n", "\n").replace("\r", "\n")
