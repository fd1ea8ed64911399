// A 3D replay of this run open in another tab: mark its current second on the charts here.
(function () {
  const box = document.getElementById("run");
  const channel = window.cloudsimReplayMark.channel(Number(box.dataset.runId));
  const charts = document.querySelector("section.charts");
  if (channel && charts) {
    channel.onmessage = (event) => window.cloudsimReplayMark.markCharts(charts, event.data.t);
  }
})();
// Live run page: poll the run's status; reload once it has ended to show charts and logs.
(function () {
  const box = document.getElementById("run");
  const settled = ["finished", "error"];
  if (settled.includes(document.getElementById("run-state").textContent)) return;
  async function poll() {
    try {
      const response = await fetch(box.dataset.statusUrl, {credentials: "same-origin"});
      if (!response.ok) throw new Error(response.status);
      const data = await response.json();
      const state = document.getElementById("run-state");
      state.textContent = data.state;
      state.className = "state " + data.state;
      document.getElementById("run-score").textContent = data.score;
      document.getElementById("run-falls").textContent = data.falls;
      document.getElementById("run-time").textContent = data.sim_seconds.toFixed(1);
      document.getElementById("run-end").textContent = data.end_reason || "";
      document.getElementById("run-error").textContent = data.error || "";
      document.getElementById("run-error").parentElement.hidden = !data.error;  // no empty row
      document.getElementById("uplink-left").textContent = data.bits_left.uplink.toLocaleString("en-US");
      document.getElementById("downlink-left").textContent = data.bits_left.downlink.toLocaleString("en-US");
      const caps = document.getElementById("caps-spent");
      caps.textContent = data.caps_spent;
      caps.className = data.caps_spent === "none" ? "" : "error";
      if (settled.includes(data.state)) { location.reload(); return; }
    } catch (e) { /* the server may be restarting: keep trying */ }
    setTimeout(poll, 1000);
  }
  poll();
})();
