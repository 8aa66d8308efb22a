// A run's page: its curves from /api/v1/runs/{id}/series, live state while it runs (the page
// reloads once the run has ended, to show its metrics), and the log tail for its owner.
"use strict";
(function () {
  const C = window.FlyboCharts;
  const charts = document.getElementById("run-charts");
  const noteEl = document.getElementById("chart-note");
  const runId = charts.dataset.run;
  const FINAL = new Set(["succeeded", "failed", "cancelled"]);
  const TOKEN_KEY = "flybo-token";

  async function drawCurves() {
    try {
      const s = await C.getJSON(`/api/v1/runs/${runId}/series`);
      C.bandChart(document.getElementById("volume-chart"),
        [{ label: "explored volume", x: s.time_s, mean: s.explored_volume_m3 }], "time, s", "m³");
      C.bandChart(document.getElementById("recall-chart"),
        [{ label: "surface recall", x: s.recall_time_s, mean: s.surface_recall.map((v) => v * 100) }],
        "time, s", "%");
      noteEl.textContent = "";
    } catch (error) {
      const text = error.status === 404 ? "The curves appear when the run has finished."
        : `Could not load the curves: ${error.message}`;
      C.note(document.getElementById("volume-chart"), text);
      C.note(document.getElementById("recall-chart"), text);
    }
  }

  async function follow() {
    try {
      const run = await C.getJSON(`/api/v1/runs/${runId}`);
      const badge = document.querySelector("#run-status [data-status]");
      badge.textContent = run.status;
      badge.className = `status status-${run.status}`;
      const bar = document.querySelector("#run-progress [data-progress]");
      bar.value = run.progress;
      document.querySelector("#run-progress [data-pct]").textContent = `${Math.round(run.progress * 100)}%`;
      if (FINAL.has(run.status)) { window.location.reload(); return; }
    } catch (error) {
      noteEl.textContent = `Could not refresh: ${error.message}. Retrying.`;
    }
    setTimeout(follow, 2000);
  }

  function logForm() {
    const form = document.getElementById("log-form");
    const input = document.getElementById("token");
    const remember = document.getElementById("remember");
    const out = document.getElementById("log");
    const saved = window.localStorage.getItem(TOKEN_KEY);
    if (saved) { input.value = saved; remember.checked = true; }
    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      const token = input.value.trim();
      if (remember.checked && token) window.localStorage.setItem(TOKEN_KEY, token);
      else window.localStorage.removeItem(TOKEN_KEY);
      out.textContent = "Loading…";
      try {
        const response = await fetch(`/api/v1/runs/${runId}/log?tail=200`,
          { headers: token ? { Authorization: `Bearer ${token}` } : {} });
        if (!response.ok) {
          let detail = response.statusText;
          try { detail = (await response.json()).detail || detail; } catch (e) { /* not JSON */ }
          out.textContent = `Refused (${response.status}): ${detail}`;
          return;
        }
        out.textContent = (await response.text()) || "The log is empty.";
      } catch (error) {
        out.textContent = `Could not load the log: ${error.message}`;
      }
    });
  }

  logForm();
  drawCurves();
  if (charts.dataset.final !== "1") setTimeout(follow, 2000);
})();
