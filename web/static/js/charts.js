// Shared chart helpers on uPlot (web/static/vendor/uplot): line charts with min-max bands,
// resized with their container. Each chart is kept on its element (el.chart) and in
// window.flyboCharts so that tests and the console can read the data points it holds.
"use strict";
window.flyboCharts = window.flyboCharts || {};
window.FlyboCharts = (function () {
  // Okabe-Ito colours: distinguishable with the common colour-vision deficiencies.
  const PALETTE = ["#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", "#000000"];

  function colour(i) { return PALETTE[i % PALETTE.length]; }

  function alpha(hex, a) {
    const n = parseInt(hex.slice(1), 16);
    return `rgba(${(n >> 16) & 255},${(n >> 8) & 255},${n & 255},${a})`;
  }

  function height() { return window.innerWidth < 600 ? 260 : 320; }

  function note(el, text) {
    el.textContent = "";
    const p = document.createElement("p");
    p.className = "note";
    p.textContent = text;
    el.appendChild(p);
  }

  function mount(el, opts, data) {
    el.textContent = "";
    const chart = new uPlot({ ...opts, width: Math.max(el.clientWidth, 200), height: height() },
      data, el);
    el.chart = chart;
    window.flyboCharts[el.id] = chart;
    let points = 0;
    for (let s = 1; s < data.length; s++) points += data[s].filter((v) => v !== null).length;
    el.dataset.points = String(points);
    if (window.ResizeObserver) {
      new ResizeObserver(() => {
        const w = Math.max(el.clientWidth, 200);
        if (Math.abs(w - chart.width) > 2) chart.setSize({ width: w, height: height() });
      }).observe(el);
    }
    return chart;
  }

  // items: [{label, x, mean, min?, max?}] -> one line per item, with its band when given.
  function bandChart(el, items, xLabel, yLabel) {
    if (!items.length) { note(el, "No curves yet."); return null; }
    const xs = Array.from(new Set(items.flatMap((it) => it.x))).sort((a, b) => a - b);
    const at = new Map(xs.map((x, i) => [x, i]));
    const data = [xs];
    const series = [{ label: xLabel }];
    const bands = [];
    const hidden = [];
    items.forEach((it, i) => {
      const c = colour(i);
      const keys = it.min && it.max ? ["mean", "min", "max"] : ["mean"];
      keys.forEach((key) => {
        const column = new Array(xs.length).fill(null);
        it.x.forEach((x, j) => { column[at.get(x)] = it[key][j]; });
        data.push(column);
        const main = key === "mean";
        series.push({ label: main ? it.label : `${it.label} ${key}`, stroke: main ? c : alpha(c, 0.35),
          width: main ? 2 : 1, spanGaps: true,
          // Short curves (a recall snapshot every 20 s) need their points to be seen at all.
          points: { show: main && xs.length <= 40, size: 6, fill: c } });
        if (!main) hidden.push(series.length - 1);
      });
      if (keys.length === 3) {
        const maxIdx = data.length - 1;
        bands.push({ series: [maxIdx, maxIdx - 1], fill: alpha(c, 0.15) });
      }
    });
    const chart = mount(el, {
      scales: { x: { time: false } }, series, bands,
      axes: [{ label: xLabel }, { label: yLabel, size: 60 }],
      legend: { live: true },
    }, data);
    // The band edges stay out of the legend: one entry per planner is what a reader needs.
    const rows = chart.root.querySelectorAll(".u-legend .u-series");
    hidden.forEach((s) => { if (rows[s]) rows[s].style.display = "none"; });
    return chart;
  }

  async function getJSON(url) {
    const response = await fetch(url, { headers: { Accept: "application/json" } });
    if (!response.ok) {
      let detail = response.statusText;
      try { detail = (await response.json()).detail || detail; } catch (e) { /* not JSON */ }
      const error = new Error(detail);
      error.status = response.status;
      throw error;
    }
    return response.json();
  }

  return { bandChart, colour, alpha, mount, note, getJSON, height };
})();
