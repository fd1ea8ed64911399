// Marks a replay's current second on a page's bandwidth charts. The 3D viewer calls it for its
// own charts and tells the run's page (open in another tab) over a BroadcastChannel.
(function () {
  function markCharts(container, t) {
    // the run runs at real time, so second N of the router's log is about simulated second N
    for (const svg of container.querySelectorAll("svg.chart[data-x-max]")) {
      let line = svg.querySelector("line.replay-mark");
      if (!line) {
        line = document.createElementNS("http://www.w3.org/2000/svg", "line");
        line.setAttribute("class", "replay-mark");
        line.setAttribute("stroke", "#8250df");
        line.setAttribute("stroke-width", "2");
        line.setAttribute("y1", svg.dataset.y0);
        line.setAttribute("y2", svg.dataset.y1);
        svg.append(line);
      }
      const x0 = +svg.dataset.x0, x1 = +svg.dataset.x1, xMax = +svg.dataset.xMax;
      const x = x0 + ((x1 - x0) * Math.min(t, xMax)) / xMax;
      line.setAttribute("x1", x.toFixed(1));
      line.setAttribute("x2", x.toFixed(1));
      line.dataset.second = Math.floor(t);
    }
  }
  function channel(runId) {
    return "BroadcastChannel" in window ? new BroadcastChannel(`cloudsim-replay-${runId}`) : null;
  }
  window.cloudsimReplayMark = { markCharts, channel };
})();
