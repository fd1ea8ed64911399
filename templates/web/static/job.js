// Live job progress: poll the job's JSON and append only the new part of its log.
(function () {
  const box = document.getElementById("job");
  const log = document.getElementById("job-log");
  if (log) log.scrollTop = log.scrollHeight;  // the newest lines matter most
  if (!box || box.dataset.final === "true") return;
  let length = log.textContent.length;
  async function poll() {
    try {
      const response = await fetch(box.dataset.progressUrl + "?since=" + length, {credentials: "same-origin"});
      if (!response.ok) throw new Error(response.status);
      const job = await response.json();
      const state = document.getElementById("job-state");
      state.textContent = job.state;
      state.className = "state " + job.state;
      document.getElementById("job-stage").textContent = job.stage || "—";
      document.getElementById("job-progress").value = job.progress;
      document.getElementById("job-percent").textContent = job.progress + "%";
      document.getElementById("job-attempts").textContent = job.attempts;
      document.getElementById("job-error").textContent = job.error || "";
      document.getElementById("job-error").parentElement.hidden = !job.error;  // no empty row
      if (job.log) { log.textContent += job.log; log.scrollTop = log.scrollHeight; }
      length = job.log_length;
      if (job.state === "succeeded" || job.state === "failed") return;
    } catch (e) { /* the server may be restarting: keep trying */ }
    setTimeout(poll, 1000);
  }
  setTimeout(poll, 500);
})();
