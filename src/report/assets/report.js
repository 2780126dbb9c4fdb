// texsyn report page behaviour (inlined by `texsyn report`; plain script, no dependencies).
//
// - Sortable tables: in every <table class="sortable">, clicking a <th> sorts the tbody rows by
//   that column; clicking it again reverses the order. Cells compare as numbers when both
//   parse as numbers (a cell's data-value, when present, is used instead of its text),
//   otherwise as strings. The sorted header carries aria-sort="ascending"/"descending".
// - Filters: <select class="filter" data-table="TABLEID" data-column="N"> (option "" = all)
//   hides the rows of TABLEID whose column N text differs from the selected value; all
//   filters on a table apply together.
// - Live reload: with <meta name="texsyn-reload" content="URL">, URL is polled every 500 ms
//   and the page reloads when the response text changes from the first one seen (or from the
//   meta's data-version, when given: the version the page was built from, which also catches
//   a rebuild that finished before the first poll). Failed requests (the server restarting)
//   and non-2xx answers are ignored.
(function () {
  'use strict';

  /** The value a cell sorts by: its data-value if present, else its text. */
  function cellValue(row, col) {
    var cell = row.cells[col];
    if (!cell) return '';
    var v = cell.getAttribute('data-value');
    return v !== null ? v : cell.textContent.trim();
  }

  /** The number a sort key denotes, or null ("" and non-numbers are not numbers). */
  function asNumber(s) {
    if (s === '') return null;
    var n = Number(s);
    if (!isNaN(n)) return n;
    var lower = s.toLowerCase();
    if (lower === 'inf' || lower === '+inf' || lower === 'infinity') return Infinity;
    if (lower === '-inf' || lower === '-infinity') return -Infinity;
    return null;
  }

  function compare(a, b) {
    var x = asNumber(a);
    var y = asNumber(b);
    if (x !== null && y !== null) return x < y ? -1 : x > y ? 1 : 0;
    return a.localeCompare(b, undefined, { numeric: true });
  }

  /** The column index of a header cell, counting colspans. */
  function columnOf(th) {
    var col = 0;
    for (var c = th.parentNode.firstElementChild; c && c !== th; c = c.nextElementSibling) {
      col += c.colSpan || 1;
    }
    return col;
  }

  function sortTable(table, th) {
    var col = columnOf(th);
    var dir = th.getAttribute('aria-sort') === 'ascending' ? 'descending' : 'ascending';
    var sign = dir === 'ascending' ? 1 : -1;
    var headers = table.querySelectorAll('thead th, tr:first-child > th');
    for (var i = 0; i < headers.length; i++) headers[i].removeAttribute('aria-sort');
    th.setAttribute('aria-sort', dir);
    var bodies = table.tBodies;
    for (var b = 0; b < bodies.length; b++) {
      var rows = Array.prototype.slice.call(bodies[b].rows);
      // Skip a header row that lives in the tbody (tables without <thead>).
      var head = rows.length && rows[0].contains(th) ? rows.shift() : null;
      var keyed = rows.map(function (row, index) {
        return { row: row, key: cellValue(row, col), index: index };
      });
      keyed.sort(function (p, q) {
        return sign * compare(p.key, q.key) || p.index - q.index; // stable
      });
      var frag = document.createDocumentFragment();
      if (head) frag.appendChild(head);
      keyed.forEach(function (k) { frag.appendChild(k.row); });
      bodies[b].appendChild(frag);
    }
  }

  function setUpSorting() {
    var tables = document.querySelectorAll('table.sortable');
    Array.prototype.forEach.call(tables, function (table) {
      var headRow = table.tHead ? table.tHead.rows[0] : table.rows[0];
      if (!headRow) return;
      Array.prototype.forEach.call(headRow.cells, function (th) {
        if (th.tagName !== 'TH') return;
        th.style.cursor = 'pointer';
        th.title = th.title || 'click to sort';
        th.addEventListener('click', function () { sortTable(table, th); });
      });
    });
  }

  function applyFilters(tableId) {
    var table = document.getElementById(tableId);
    if (!table) return;
    var selects = document.querySelectorAll('select.filter[data-table="' + tableId + '"]');
    var active = [];
    Array.prototype.forEach.call(selects, function (s) {
      if (s.value !== '') active.push({ col: Number(s.getAttribute('data-column')), value: s.value });
    });
    Array.prototype.forEach.call(table.tBodies, function (body) {
      Array.prototype.forEach.call(body.rows, function (row) {
        if (row.querySelector('th') && !row.querySelector('td')) return; // header row
        var shown = active.every(function (f) {
          var cell = row.cells[f.col];
          return cell && cell.textContent.trim() === f.value;
        });
        row.hidden = !shown;
      });
    });
  }

  function setUpFilters() {
    var selects = document.querySelectorAll('select.filter[data-table]');
    Array.prototype.forEach.call(selects, function (s) {
      var tableId = s.getAttribute('data-table');
      s.addEventListener('change', function () { applyFilters(tableId); });
      if (s.value !== '') applyFilters(tableId); // a value restored by the browser
    });
  }

  function setUpReload() {
    var meta = document.querySelector('meta[name="texsyn-reload"]');
    if (!meta || !window.fetch) return;
    var url = meta.getAttribute('content');
    var first = meta.getAttribute('data-version'); // null when absent
    var busy = false;
    setInterval(function () {
      if (busy) return;
      busy = true;
      fetch(url, { cache: 'no-store' })
        .then(function (r) { return r.ok ? r.text() : null; })
        .then(function (text) {
          if (text === null) return;
          if (first === null) first = text;
          else if (text !== first) location.reload();
        })
        .catch(function () { /* server restarting: try again next tick */ })
        .then(function () { busy = false; });
    }, 500);
  }

  function init() {
    setUpSorting();
    setUpFilters();
    setUpReload();
  }

  if (document.readyState === 'loading') {
    document.addEventListener('DOMContentLoaded', init);
  } else {
    init();
  }
})();
