// Sortable tables: a click on a header button reorders the body rows by that column.
// Cells carry their sort value in data-sort (numbers as text); an empty data-sort is a
// missing value and stays at the bottom in both directions.
"use strict";
(function () {
  function cellValue(row, index) {
    const cell = row.cells[index];
    if (!cell) return null;
    const raw = cell.hasAttribute("data-sort") ? cell.getAttribute("data-sort") : cell.textContent.trim();
    if (raw === "") return null;
    const n = Number(raw);
    return Number.isFinite(n) ? n : raw.toLowerCase();
  }

  function compare(a, b) {
    if (typeof a === "number" && typeof b === "number") return a - b;
    return String(a).localeCompare(String(b), undefined, { numeric: true });
  }

  function sortBy(table, th) {
    const headers = Array.from(th.parentElement.children);
    const index = headers.indexOf(th);
    const ascending = th.getAttribute("aria-sort") !== "ascending";
    headers.forEach((h) => h.removeAttribute("aria-sort"));
    th.setAttribute("aria-sort", ascending ? "ascending" : "descending");
    const body = table.tBodies[0];
    const rows = Array.from(body.rows).map((row, i) => ({ row, i, v: cellValue(row, index) }));
    rows.sort((x, y) => {
      if (x.v === null || y.v === null) {
        if (x.v === y.v) return x.i - y.i;
        return x.v === null ? 1 : -1;
      }
      const c = compare(x.v, y.v);
      return (ascending ? c : -c) || x.i - y.i;
    });
    rows.forEach((r) => body.appendChild(r.row));
  }

  document.querySelectorAll("table.sortable").forEach((table) => {
    table.querySelectorAll("thead th").forEach((th) => {
      const button = th.querySelector("button");
      if (button) button.addEventListener("click", () => sortBy(table, th));
    });
  });
})();
