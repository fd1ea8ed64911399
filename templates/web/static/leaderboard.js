// Live leaderboard: poll the standings and redraw the table when they change (no reload).
(function () {
  const table = document.getElementById("leaderboard");
  const note = document.getElementById("leaderboard-updated");
  const every = 3000;
  let last = null;
  function cell(text, name) {
    const td = document.createElement("td");
    if (name) td.className = name;
    td.textContent = text;  // team names are text, never markup
    return td;
  }
  function draw(standings) {
    const body = document.createElement("tbody");
    for (const s of standings) {
      const tr = document.createElement("tr");
      tr.dataset.team = s.team;
      tr.append(cell(s.rank, "rank"), cell(s.team), cell(s.runs, "runs"),
        cell(s.checkpoints, "checkpoints"), cell((100 * s.uplink_share_left).toFixed(1) + "%", "share"),
        cell(s.seconds_left.toFixed(0), "seconds"),
        cell(s.unverified ? s.unverified + " unverified" : "", "unverified"),
        cell([s.invalidated ? s.invalidated + " run(s) invalidated" : "",
          s.held ? s.held + " held for review" : ""].filter(Boolean).join(", "), "invalidated"));
      body.append(tr);
    }
    if (!standings.length) {
      const td = cell("No teams yet.");
      td.colSpan = 8;
      body.append(document.createElement("tr"));
      body.lastChild.append(td);
    }
    table.tBodies[0].replaceWith(body);
  }
  async function poll() {
    try {
      const response = await fetch(table.dataset.url, {credentials: "same-origin"});
      if (!response.ok) throw new Error(response.status);
      const text = await response.text();
      if (text !== last) {
        draw(JSON.parse(text));
        last = text;
      }
      note.textContent = "Updated " + new Date().toLocaleTimeString();
    } catch (e) { /* the server may be restarting: keep trying */ }
    setTimeout(poll, every);
  }
  poll();
})();
