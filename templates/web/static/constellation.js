// Live constellation page: poll its status and refresh states, addresses, progress and log.
(function () {
  const box = document.getElementById("constellation");
  if (!box) return;
  const log = document.getElementById("job-log");
  if (log) log.scrollTop = log.scrollHeight;  // the newest lines matter most
  const settled = ["ready", "error", "terminated", "terminate_incomplete"];
  async function poll() {
    try {
      const response = await fetch(box.dataset.statusUrl, {credentials: "same-origin"});
      if (!response.ok) throw new Error(response.status);
      const data = await response.json();
      const state = document.getElementById("c-state");
      state.textContent = data.state;
      state.className = "state " + data.state;
      document.getElementById("c-error").textContent =
        (data.error_code ? data.error_code + " " : "") + (data.error || "");
      document.getElementById("c-error").parentElement.hidden = !data.error;  // no empty row
      document.getElementById("c-step").textContent = data.step || "—";
      const since = document.getElementById("c-step-since");
      if (since) since.textContent = data.step_since || "";
      for (const m of data.machines) {
        const row = document.querySelector(`tr[data-machine="${m.name}"]`);
        if (!row) continue;
        row.querySelector(".private").textContent = m.private_ip || "";
        row.querySelector(".public").textContent = m.public_ip || "";
        row.querySelector(".state-cell").innerHTML = `<span class="state ${m.state}">${m.state}</span>`;
        row.querySelector(".heard").textContent = m.heard || "—";
      }
      if (data.job) {
        const stage = document.getElementById("job-stage");
        if (stage) {
          stage.textContent = data.job.stage || "—";
          document.getElementById("job-progress").value = data.job.progress;
          document.getElementById("job-percent").textContent = data.job.progress + "%";
        }
      }
      if (settled.includes(data.state) && (!data.job || ["succeeded", "failed"].includes(data.job.state))) {
        if (box.dataset.wasBusy === "true") { location.reload(); return; }  // show the results
        setTimeout(poll, 2000);  // settled: only the machines' last-heard times still move
        return;
      }
      box.dataset.wasBusy = "true";
    } catch (e) { /* the server may be restarting: keep trying */ }
    setTimeout(poll, 1000);
  }
  poll();
})();
