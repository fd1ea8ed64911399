// A 3D replay of this run open in another tab: mark its current second on the charts here.
(function () {
  const box = document.getElementById("run");
  const channel = window.cloudsimReplayMark.channel(Number(box.dataset.runId));
  const charts = document.querySelector("section.charts");
  if (channel && charts) {
    channel.onmessage = (event) => window.cloudsimReplayMark.markCharts(charts, event.data.t);
  }
})();
// Live run page: poll the run's live figures every second (the server reads them from a cache
// the live reader refreshes once a second); reload once it has ended to show the stored logs.
(function () {
  const box = document.getElementById("run");
  const settled = ["finished", "error", "needs_review"];
  if (settled.includes(document.getElementById("run-state").textContent)) return;
  const text = (id, value) => { document.getElementById(id).textContent = value; };
  function cell(row, value) {
    const td = document.createElement("td");
    td.textContent = value;
    row.appendChild(td);
  }
  function events(list) {
    const body = document.getElementById("score-events");
    if (!list.length) return;
    body.replaceChildren(...list.map((e) => {
      const row = document.createElement("tr");
      cell(row, e.sim_time.toFixed(2));
      cell(row, e.kind);
      cell(row, `${e.checkpoint ?? ""} ${e.description}`);
      cell(row, e.wall_time);
      return row;
    }));
  }
  function heard(map) {
    const list = document.getElementById("run-heard");
    const roles = Object.keys(map).sort();
    if (!roles.length) return;
    list.replaceChildren(...roles.map((role) => {
      const item = document.createElement("li");
      item.dataset.role = role;
      const time = document.createElement("time");
      time.textContent = map[role];
      item.append(`${role}: `, time);
      return item;
    }));
  }
  function flags(list) {
    document.getElementById("run-flags").replaceChildren(...list.map((f) => {
      const p = document.createElement("p");
      p.className = "error";
      p.dataset.code = f.code;
      const code = document.createElement("code");
      code.textContent = f.code;
      const remedy = document.createElement("em");
      remedy.textContent = f.remedy;
      p.append(code, ` ${f.cause} ${f.figures || ""} `, remedy);
      return p;
    }));
  }
  // The charts are SVG the server draws (every text in it escaped there), as on first load.
  function charts(data) {
    if (!data) return;
    document.getElementById("score-chart").innerHTML = data.score;
    const section = document.getElementById("bandwidth-charts");
    if (data.bandwidth.length) {
      section.innerHTML = data.bandwidth.map((svg) => `<figure>${svg}</figure>`).join("");
      const waiting = document.getElementById("bandwidth-waiting");
      if (waiting) waiting.remove();
    }
  }
  async function poll() {
    const started = Date.now();  // one poll a second, however long an answer takes
    try {
      const response = await fetch(box.dataset.statusUrl, {credentials: "same-origin"});
      if (!response.ok) throw new Error(response.status);
      const data = await response.json();
      const state = document.getElementById("run-state");
      state.textContent = data.state;
      state.className = "state " + data.state;
      text("run-since", data.since || "");
      text("run-score", data.score);
      text("run-falls", data.falls);
      text("run-time", data.sim_seconds.toFixed(1));
      text("run-rtf", data.rtf === null ? "—" : data.rtf.toFixed(2));
      text("run-end", data.end_reason || "");
      text("run-error", (data.error_code ? data.error_code + " " : "") + (data.error || ""));
      document.getElementById("run-error").parentElement.hidden = !data.error;  // no empty row
      text("uplink-left", data.bits_left.uplink.toLocaleString("en-US"));
      text("downlink-left", data.bits_left.downlink.toLocaleString("en-US"));
      const caps = document.getElementById("caps-spent");
      caps.textContent = data.caps_spent;
      caps.className = data.caps_spent === "none" ? "" : "error";
      events(data.events);
      heard(data.heard);
      flags(data.flags);
      charts(data.charts);
      if (settled.includes(data.state)) { location.reload(); return; }
    } catch (e) { /* the server may be restarting: keep trying */ }
    setTimeout(poll, Math.max(0, 1000 - (Date.now() - started)));
  }
  poll();
})();
