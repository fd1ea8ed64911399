// Dashboard run cards: follow each live run's figures every second, as its page does.
(function () {
  const settled = ["finished", "error", "needs_review"];
  function follow(card) {
    const put = (name, value) => { card.querySelector(`[data-live="${name}"]`).textContent = value; };
    async function poll() {
      const started = Date.now();
      try {
        const response = await fetch(card.dataset.statusUrl, {credentials: "same-origin"});
        if (!response.ok) throw new Error(response.status);
        const data = await response.json();
        put("state", data.state);
        card.querySelector('[data-live="state"]').className = "state " + data.state;
        put("sim_seconds", data.sim_seconds.toFixed(1));
        put("rtf", data.rtf === null ? "—" : data.rtf.toFixed(2));
        put("score", data.score);
        put("falls", data.falls);
        put("uplink_left", data.bits_left.uplink.toLocaleString("en-US"));
        put("downlink_left", data.bits_left.downlink.toLocaleString("en-US"));
        put("flags", data.flags.map((f) => f.code).join(" "));
        if (settled.includes(data.state)) return;
      } catch (e) { /* the server may be restarting: keep trying */ }
      setTimeout(poll, Math.max(0, 1000 - (Date.now() - started)));
    }
    poll();
  }
  document.querySelectorAll("article.run-card").forEach(follow);
})();
