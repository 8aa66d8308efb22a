// Live progress of a job: polls /api/v1/jobs/{id} every 2 s and updates the job's and each
// run's state and progress bar in place, until the job has reached a final state.
"use strict";
(function () {
  const root = document.getElementById("job");
  if (!root) return;
  const FINAL = new Set(["succeeded", "failed", "cancelled"]);
  const live = document.getElementById("job-live");

  function setStatus(container, status) {
    const badge = container && container.querySelector("[data-status]");
    if (!badge) return;
    badge.textContent = status;
    badge.className = `status status-${status}`;
    const cell = badge.closest("td");
    if (cell) cell.dataset.sort = status;
  }

  function setProgress(container, value) {
    if (!container) return;
    const bar = container.querySelector("[data-progress]");
    const pct = container.querySelector("[data-pct]");
    if (bar) { bar.value = value; bar.textContent = `${Math.round(value * 100)}%`; }
    if (pct) pct.textContent = `${Math.round(value * 100)}%`;
    const cell = bar && bar.closest("td");
    if (cell) cell.dataset.sort = String(value);
  }

  async function poll() {
    try {
      const response = await fetch(`/api/v1/jobs/${root.dataset.job}`, { headers: { Accept: "application/json" } });
      if (!response.ok) throw new Error(response.statusText);
      const job = await response.json();
      setStatus(document.getElementById("job-status"), job.status);
      setProgress(document.getElementById("job-progress"), job.progress);
      job.runs.forEach((run) => {
        const row = root.querySelector(`tr[data-run="${run.id}"]`);
        setStatus(row, run.status);
        setProgress(row, run.progress);
      });
      root.dataset.polls = String(Number(root.dataset.polls || 0) + 1);
      if (FINAL.has(job.status)) {
        root.dataset.final = "1";
        live.textContent = `The job has ${job.status}.`;
        return;
      }
      live.textContent = "";
    } catch (error) {
      live.textContent = `Could not refresh: ${error.message}. Retrying.`;
    }
    setTimeout(poll, 2000);
  }

  if (root.dataset.final !== "1") setTimeout(poll, 2000);
})();
