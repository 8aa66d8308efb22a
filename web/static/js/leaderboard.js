// The leaderboard's figures: explored volume and surface recall over time on the chosen area
// (the paper's Figures 4 and 5) from /api/v1/curves (of the page's benchmark version), and coverage rank against F-score rank
// with the Pareto set (Figure 6) from the ranks in Table 2's rows, each with its 95 % interval.
"use strict";
(function () {
  const C = window.FlyboCharts;
  const volumeEl = document.getElementById("volume-chart");
  const recallEl = document.getElementById("recall-chart");
  const paretoEl = document.getElementById("pareto-chart");

  async function curves() {
    if (!volumeEl) return;
    const query = new URLSearchParams({ preset: volumeEl.dataset.preset, area: volumeEl.dataset.area,
                                        benchmark_version: volumeEl.dataset.benchmarkVersion });
    try {
      const body = await C.getJSON(`/api/v1/curves?${query}`);
      const pick = (key, timeKey, scale) => body.planners.map((p) => ({
        label: `${p.planner} (${p.runs})`, x: p[timeKey],
        mean: p[key].mean.map((v) => (v === null ? null : v * scale)),
        min: p[key].min.map((v) => (v === null ? null : v * scale)),
        max: p[key].max.map((v) => (v === null ? null : v * scale)),
      }));
      C.bandChart(volumeEl, pick("explored_volume_m3", "time_s", 1), "time, s", "explored volume, m³");
      C.bandChart(recallEl, pick("surface_recall", "recall_time_s", 100), "time, s", "surface recall, %");
    } catch (error) {
      C.note(volumeEl, `Could not load the curves: ${error.message}`);
      C.note(recallEl, `Could not load the curves: ${error.message}`);
    }
  }

  function bound(text) {
    return text === undefined || text === "" ? null : Number(text);
  }

  function pareto() {
    if (!paretoEl) return;
    const table = document.getElementById(paretoEl.dataset.source);
    const points = Array.from(table ? table.querySelectorAll("tbody tr[data-planner]") : [])
      .filter((tr) => tr.dataset.fscoreRank !== "")
      .map((tr) => ({ name: tr.dataset.planner, x: Number(tr.dataset.coverageRank),
                      y: Number(tr.dataset.fscoreRank), pareto: tr.dataset.pareto === "1",
                      // The 95 % intervals of both mean ranks, drawn as error bars.
                      x0: bound(tr.dataset.coverageRankLow), x1: bound(tr.dataset.coverageRankHigh),
                      y0: bound(tr.dataset.fscoreRankLow), y1: bound(tr.dataset.fscoreRankHigh) }))
      .sort((a, b) => a.x - b.x || a.y - b.y);
    if (!points.length) { C.note(paretoEl, "No planner has both ranks yet."); return; }
    const top = Math.max(...points.map((p) => Math.max(p.x, p.y, p.x1 ?? 0, p.y1 ?? 0))) + 0.5;
    const labels = {
      hooks: { draw: [(u) => {
        const ctx = u.ctx;
        ctx.save();
        ctx.strokeStyle = "#4a5560";
        ctx.lineWidth = devicePixelRatio;
        points.forEach((p) => {
          const px = u.valToPos(p.x, "x", true), py = u.valToPos(p.y, "y", true);
          ctx.beginPath();
          if (p.x0 !== null && p.x1 !== null) {
            ctx.moveTo(u.valToPos(p.x0, "x", true), py);
            ctx.lineTo(u.valToPos(p.x1, "x", true), py);
          }
          if (p.y0 !== null && p.y1 !== null) {
            ctx.moveTo(px, u.valToPos(p.y0, "y", true));
            ctx.lineTo(px, u.valToPos(p.y1, "y", true));
          }
          ctx.stroke();
        });
        ctx.fillStyle = "#14171a";
        ctx.font = `${Math.round(12 * devicePixelRatio)}px system-ui, sans-serif`;
        points.forEach((p) => {
          ctx.fillText(p.name, u.valToPos(p.x, "x", true) + 8 * devicePixelRatio,
                       u.valToPos(p.y, "y", true) - 6 * devicePixelRatio);
        });
        ctx.restore();
      }] },
    };
    C.mount(paretoEl, {
      mode: 1, plugins: [labels],
      scales: { x: { time: false, range: [0.5, top] }, y: { range: [0.5, top] } },
      axes: [{ label: "mean coverage rank (1 is best)" }, { label: "mean F-score rank", size: 50 }],
      series: [
        { label: "coverage rank" },
        { label: "planners", stroke: C.colour(0), paths: () => null,
          points: { show: true, size: 10, fill: C.colour(0) } },
        { label: "Pareto set", stroke: C.colour(1), width: 2, spanGaps: true,
          points: { show: true, size: 14, fill: "rgba(0,0,0,0)", stroke: C.colour(1), width: 2 } },
      ],
    }, [points.map((p) => p.x), points.map((p) => p.y), points.map((p) => (p.pareto ? p.y : null))]);
  }

  pareto();
  curves();
})();
