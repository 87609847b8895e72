"""The Pareto plot of a bench: render time against image error, one point per setting."""

from __future__ import annotations

from pathlib import Path

import plotly.graph_objects as go

from sweep3d.bench.measurement import BenchRow, pareto
from sweep3d.cache import atomic_write


def write_pareto_plot(rows: list[BenchRow], recommended: BenchRow | None, path: Path, title: str) -> Path:
    """Write a self-contained HTML plot (plotly inlined) and return its path."""
    front = sorted(pareto([r for r in rows if r.is_setting]), key=lambda r: r.seconds)
    fig = go.Figure()
    others = [r for r in rows if r.is_setting]
    fig.add_trace(go.Scatter(
        x=[r.seconds for r in others], y=[r.psnr for r in others], mode="markers+text",
        text=[r.setting.label() for r in others], textposition="top center", name="settings",
        marker={"size": 10, "color": [r.top1_agreement for r in others], "colorscale": "RdYlGn",
                "cmin": 0.5, "cmax": 1.0, "colorbar": {"title": "top-1 agreement"}},
        customdata=[[r.ssim, r.top1_agreement, r.verdict_agreement] for r in others],
        hovertemplate="%{text}<br>%{x:.3f} s/image, %{y:.1f} dB, SSIM %{customdata[0]:.3f}"
                      "<br>top-1 agreement %{customdata[1]:.0%}, verdict %{customdata[2]:.0%}<extra></extra>"))
    fig.add_trace(go.Scatter(x=[r.seconds for r in front], y=[r.psnr for r in front], mode="lines",
                             name="Pareto front", line={"dash": "dot", "color": "#555"}))
    if recommended is not None:
        fig.add_trace(go.Scatter(x=[recommended.seconds], y=[recommended.psnr], mode="markers", name="recommended",
                                 marker={"size": 20, "symbol": "circle-open", "line": {"width": 3, "color": "#1f5fbf"}}))
    fig.update_layout(title=title, xaxis={"title": "steady-state render seconds per image (log)", "type": "log"},
                      yaxis={"title": "PSNR against the reference (dB)"}, template="plotly_white", height=640)
    atomic_write(path, fig.to_html(include_plotlyjs=True, full_html=True).encode("utf-8"))
    return path
