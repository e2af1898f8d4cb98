// isf show: the page's script. Reads the JSON in #isf-data (isf/viewer/report.py), draws the
// object, the gripper at the chosen grasp and its convergence plot with plotly.js (inlined).
"use strict";
(function () {
  const data = JSON.parse(document.getElementById("isf-data").textContent);

  function decode(text, Type) {
    const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
    return new Type(bytes.buffer);
  }
  function columns(flat) { // (N*3) -> [x, y, z]
    const n = flat.length / 3, x = new Float32Array(n), y = new Float32Array(n), z = new Float32Array(n);
    for (let a = 0; a < n; a++) { x[a] = flat[3 * a]; y[a] = flat[3 * a + 1]; z[a] = flat[3 * a + 2]; }
    return [x, y, z];
  }
  function mesh(m) {
    const v = decode(m.vertices, Float32Array), f = decode(m.faces, Int32Array);
    const [i, j, k] = columns(f);
    return { v: v, i: Array.from(i), j: Array.from(j), k: Array.from(k) };
  }
  function place(local, T, offset, out, start) { // out[start..] = T (3x4 at T[offset]) * local
    for (let a = 0; a < local.length; a += 3) {
      const x = local[a], y = local[a + 1], z = local[a + 2], o = start + a;
      for (let r = 0; r < 3; r++) {
        const b = offset + 4 * r;
        out[o + r] = T[b] * x + T[b + 1] * y + T[b + 2] * z + T[b + 3];
      }
    }
  }

  // the gripper: its parts concatenated into one mesh, placed per grasp
  const parts = data.parts.map(mesh);
  const gi = [], gj = [], gk = [];
  let nVertices = 0;
  parts.forEach((p) => {
    p.start = nVertices;
    p.i.forEach((v, a) => { gi.push(v + nVertices); gj.push(p.j[a] + nVertices); gk.push(p.k[a] + nVertices); });
    nVertices += p.v.length / 3;
  });
  const contactLocal = decode(data.contacts.points, Float32Array);
  const contactLink = decode(data.contacts.link, Int32Array);
  const range = 1000 * data.contacts.range;

  function gripperAt(g) {
    const out = new Float32Array(3 * nVertices);
    parts.forEach((p, n) => place(p.v, g.T_parts, 12 * n, out, 3 * p.start));
    return columns(out);
  }
  function contactsAt(g) {
    const out = new Float32Array(contactLocal.length);
    for (let a = 0; a < contactLink.length; a++) {
      place(contactLocal.subarray(3 * a, 3 * a + 3), g.T_links, 12 * contactLink[a], out, 3 * a);
    }
    const d = Array.from(decode(g.distance, Float32Array), (v) => 1000 * v);
    return [columns(out), d];
  }
  function colour(g) {
    return g.valid ? "#4a78c2" : (g.collision_free ? "#e0a030" : "#d03030");
  }

  // the 3D view
  const traces = [];
  if (data.object.kind === "mesh") {
    const m = mesh(data.object), [x, y, z] = columns(m.v);
    traces.push({ type: "mesh3d", name: "object", x: x, y: y, z: z, i: m.i, j: m.j, k: m.k,
      color: "#c8bfa8", opacity: 0.55, hoverinfo: "skip" });
  } else {
    const [x, y, z] = columns(decode(data.object.points, Float32Array));
    traces.push({ type: "scatter3d", mode: "markers", name: "object", x: x, y: y, z: z,
      marker: { size: 1.5, color: "#8a8270" }, hoverinfo: "skip" });
  }
  if (data.table) {
    const m = mesh(data.table), [x, y, z] = columns(m.v);
    traces.push({ type: "mesh3d", name: "table", x: x, y: y, z: z, i: m.i, j: m.j, k: m.k,
      color: "#9a9a9a", opacity: 0.35, hoverinfo: "skip" });
  }
  if (data.unseen && data.unseen.max > 0) {
    const [x, y, z] = columns(decode(data.unseen.points, Float32Array));
    traces.push({ type: "isosurface", name: "unseen space", x: x, y: y, z: z,
      value: decode(data.unseen.depth, Float32Array), isomin: 1e-4, isomax: data.unseen.max,
      surface: { count: 1 }, caps: { x: { show: false }, y: { show: false }, z: { show: false } },
      colorscale: [[0, "#6a5acd"], [1, "#6a5acd"]], showscale: false, opacity: 0.12, hoverinfo: "skip" });
  }
  const first = data.grasps[0];
  const GRIPPER = traces.length, CONTACTS = traces.length + 1;
  if (first) {
    const [x, y, z] = gripperAt(first);
    traces.push({ type: "mesh3d", name: "gripper", x: x, y: y, z: z, i: gi, j: gj, k: gk,
      color: colour(first), hoverinfo: "skip" });
    const [[cx, cy, cz], d] = contactsAt(first);
    traces.push({ type: "scatter3d", mode: "markers", name: "contact points", x: cx, y: cy, z: cz,
      text: d.map((v) => v.toFixed(2) + " mm"), hoverinfo: "text",
      marker: { size: 2.5, color: d, cmin: -range, cmax: range, colorscale: "RdBu",
        colorbar: { title: { text: "distance, mm" }, thickness: 12, len: 0.6 } } });
  }
  const view = document.getElementById("view");
  Plotly.newPlot(view, traces, {
    margin: { l: 0, r: 0, t: 0, b: 0 }, showlegend: false, uirevision: "keep",
    scene: { aspectmode: "data", xaxis: { title: { text: "x, m" } }, yaxis: { title: { text: "y, m" } },
      zaxis: { title: { text: "z, m" } } },
  }, { displaylogo: false, responsive: true });

  // the convergence plot (Fig. 5): mean distance and finger displacement per ISF iteration
  const plot = document.getElementById("plot");
  function convergence(g) {
    const c = g.convergence;
    if (!c) {
      return [[], { annotations: [{ text: "no convergence record in this plan file (written by an older isf)",
        showarrow: false, xref: "paper", yref: "paper", x: 0.5, y: 0.5 }] }];
    }
    const it = c.level.map((_, a) => a); // entry 0 is the start, then one per ISF iteration
    const out = [{ type: "scatter", mode: "lines+markers", name: "mean distance, mm", x: it,
      y: c.mean_distance.map((v) => (v === null ? null : 1000 * v)), line: { color: "#2060c0" },
      text: c.ipfo_iterations.map((n, a) => "level " + c.level[a] + ", " + n + " IPFO iterations"),
      hovertemplate: "iteration %{x}: %{y:.3f} mm<br>%{text}<extra></extra>" }];
    const shades = ["#c03030", "#e07020", "#a0306a", "#806000", "#d05090", "#704020"];
    Object.entries(c.joints).forEach(([name, values], n) => {
      const unit = data.joint_units[name] || "";
      const factor = unit === "mm" ? 1000 : (unit === "deg" ? 180 / Math.PI : 1);
      out.push({ type: "scatter", mode: "lines", name: name + ", " + unit, x: it, yaxis: "y2",
        y: values.map((v) => (v === null ? null : factor * v)), line: { color: shades[n % shades.length], dash: "dot" } });
    });
    out.push({ type: "bar", name: "IPFO iterations", x: it, y: c.ipfo_iterations, yaxis: "y3",
      marker: { color: "#999" } });
    const shapes = [], notes = [];
    c.level.forEach((level, a) => {
      if (a === 0 || level !== c.level[a - 1]) {
        shapes.push({ type: "line", xref: "x", yref: "paper", x0: a - 0.5, x1: a - 0.5, y0: 0, y1: 1,
          line: { color: "#bbb", dash: "dash", width: 1 } });
        notes.push({ text: "level " + level, x: a - 0.5, xref: "x", y: 1, yref: "paper",
          xanchor: "left", showarrow: false, font: { size: 10, color: "#777" } });
      }
    });
    return [out, { shapes: shapes, annotations: notes }];
  }
  function plotLayout(g, extra) {
    return Object.assign({
      title: { text: "grasp " + g.rank + ": ISF convergence", font: { size: 13 } },
      margin: { l: 60, r: 60, t: 30, b: 35 }, legend: { orientation: "h", y: -0.2 },
      xaxis: { title: { text: "ISF iteration (0: the start)" }, anchor: "y3" },
      yaxis: { title: { text: "mean distance, mm" }, domain: [0.3, 1] },
      yaxis2: { title: { text: "finger" }, overlaying: "y", side: "right", anchor: "x" },
      yaxis3: { title: { text: "IPFO" }, domain: [0, 0.22] },
    }, extra);
  }

  // the list of grasps
  const mm = (v) => (v === null || v === undefined ? "-" : (1000 * v).toFixed(2));
  const num = (v) => (v === null || v === undefined ? "-" : v.toFixed(3));
  const yes = (v) => (v === null || v === undefined ? "<td>-</td>" : (v ? "<td class=yes>yes</td>" : "<td class=no>no</td>"));
  const list = document.getElementById("list");
  list.innerHTML = "<table><thead><tr><th>rank</th><th>valid</th><th>collision-free</th>" +
    "<th>mean distance, mm</th><th>clearance, mm</th><th>penetration, mm</th><th>iterations</th>" +
    "<th>status</th><th>squeeze imbalance</th><th>epsilon</th><th>gravity margin</th><th>physics</th></tr></thead><tbody>" + data.grasps.map((g, n) =>
      "<tr class=grasp data-index=" + n + " title='" + (g.repaired ? "repaired; " : "") + (g.centred ? "centred; " : "") +
      (g.duplicate_of ? "duplicate of " + g.duplicate_of + "; " : "") +
      (g.closing_obstructed_by.length ? "closing obstructed by: " + g.closing_obstructed_by.join(", ") + "; " : "") +
      (g.colliding_links.length ? "colliding: " + g.colliding_links.join(", ") : "") + "'><td>" + g.rank + "</td>" +
      yes(g.valid) + yes(g.collision_free) + "<td>" + mm(g.mean_distance) + "</td><td>" + mm(g.clearance) +
      "</td><td>" + mm(g.penetration) + "</td><td>" + g.iterations + "</td><td>" + g.status + "</td><td>" +
      num(g.squeeze_imbalance) + "</td><td>" + num(g.epsilon) + "</td><td>" + num(g.min_margin) + "</td><td>" + (g.physics || "-") + "</td></tr>").join("") +
    "</tbody></table>";

  function choose(n) {
    const g = data.grasps[n];
    if (!g) return;
    list.querySelectorAll("tr.chosen").forEach((r) => r.classList.remove("chosen"));
    list.querySelector("tr[data-index='" + n + "']").classList.add("chosen");
    const [x, y, z] = gripperAt(g);
    Plotly.restyle(view, { x: [x], y: [y], z: [z], color: [colour(g)] }, [GRIPPER]);
    const [[cx, cy, cz], d] = contactsAt(g);
    Plotly.restyle(view, { x: [cx], y: [cy], z: [cz], "marker.color": [d],
      text: [d.map((v) => v.toFixed(2) + " mm")] }, [CONTACTS]);
    const [traces2, extra] = convergence(g);
    Plotly.react(plot, traces2, plotLayout(g, extra), { displaylogo: false, responsive: true });
    document.body.dataset.chosen = String(g.rank);
  }
  list.addEventListener("click", (event) => {
    const row = event.target.closest("tr.grasp");
    if (row) choose(Number(row.dataset.index));
  });
  if (first) choose(0);
  document.body.dataset.ready = "1";
})();
