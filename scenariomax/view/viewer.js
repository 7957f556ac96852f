/* V-Max scenario viewer: plain JavaScript, no dependencies, no network beyond the serving host.
   Scenes are packed by scenariomax/view/scene.py:  uint32 header length | JSON header | pad to 8 | arrays.
   URL parameters (also a test hook): ?scenario=ID  ?frame=N  ?layers=name,name  ?metric=NAME  ?play=1
   ?view=X,Y,PIXELS_PER_METRE (centre in the data's coordinates)  ?hover=X,Y (show the tooltip there) */
(function () {
  "use strict";
  var CONFIG = JSON.parse(document.getElementById("vmax-config").textContent);
  var PARAMS = new URLSearchParams(window.location.search);
  var $ = function (id) { return document.getElementById(id); };
  var errors = [];
  window.addEventListener("error", function (e) { errors.push(String(e.message)); setStatus(); });

  var OBJECT_COLORS = { 1: "#2a6fdb", 2: "#f28e2b", 3: "#3cb44b", 4: "#8c6d4f" };
  var OBJECT_NAMES = { 0: "unset", 1: "vehicle", 2: "pedestrian", 3: "cyclist", 4: "other" };
  var SDC_COLOR = "#e6007e";
  var SIM_COLORS = ["#a6ff00", "#b15cff", "#ffffff", "#ffe600", "#222222", "#00ffd0"];
  var LIGHT_COLORS = { 1: "#e8281e", 4: "#e8281e", 7: "#e8281e", 2: "#ffd21f", 5: "#ffd21f", 8: "#ffd21f",
                       3: "#2fd24a", 6: "#2fd24a" };
  var LIGHT_NAMES = { 0: "unknown", 1: "arrow stop", 2: "arrow caution", 3: "arrow go", 4: "stop", 5: "caution",
                      6: "go", 7: "flashing stop", 8: "flashing caution" };
  var FAIL_METRICS = { overlap: "collision", offroad: "off-road", red_light: "red light",
                       at_fault_collision: "at-fault collision" };
  var TRAIL_STEPS = 30;
  var LAYERS = [
    ["lanes", "lane centres", true], ["lines", "road lines", true], ["edges", "road edges", true],
    ["crosswalks", "crosswalks", true], ["stops", "stop signs", true], ["bumps", "speed bumps", true],
    ["lights", "traffic lights", true], ["paths", "SDC paths", true], ["agentpaths", "agent paths", false],
    ["controllable", "controllable", true], ["trails", "trails", true], ["sdclog", "SDC log", true],
    ["objects", "objects", true], ["sims", "rollouts", true]
  ];

  var state = {
    entries: [], filtered: [], sel: -1, scene: null, t: 0, playing: false, speed: 1, lastTick: 0, acc: 0,
    view: { cx: 0, cy: 0, k: 4 }, layers: {}, cache: {}, loading: -1, drawn: 0, metric: null, sdcPx: null
  };
  var wantLayers = PARAMS.get("layers");
  LAYERS.forEach(function (l) { state.layers[l[0]] = wantLayers ? wantLayers.split(",").indexOf(l[0]) >= 0 : l[2]; });

  // ------------------------------------------------------------------ decoding
  var TYPED = { i16: Int16Array, u16: Uint16Array, u8: Uint8Array, i32: Int32Array, f32: Float32Array };

  function decodeScene(buffer) {
    var view = new DataView(buffer);
    var length = view.getUint32(0, true);
    var header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
    var start = 4 + length + ((8 - ((4 + length) % 8)) % 8);
    var a = {};
    Object.keys(header.arrays).forEach(function (name) {
      var spec = header.arrays[name];
      a[name] = new TYPED[spec[0]](buffer, start + spec[1], spec[2]);
    });
    var m = header.meta;
    var s = { meta: m, a: a, T: m.num_steps || 1, N: m.num_objects || 0, scale: m.scale || 0.01 };
    if (m.error) return s;
    s.L = s.T ? a.tl_state.length / s.T : 0;
    s.sims = (m.sims || []).map(function (sim, k) {
      var metrics = {};
      sim.metrics.forEach(function (name, j) { metrics[name] = a["sim" + k + "_m" + j]; });
      return { meta: sim, x: a["sim" + k + "_x"], y: a["sim" + k + "_y"], yaw: a["sim" + k + "_yaw"],
               valid: a["sim" + k + "_valid"], stepValid: a["sim" + k + "_step_valid"], metrics: metrics,
               color: SIM_COLORS[k % SIM_COLORS.length], failStep: firstFailure(sim) };
    });
    return s;
  }

  function firstFailure(sim) {  // timestep from which the simulated SDC is drawn failing, or -1
    var best = -1;
    (sim.failures || []).forEach(function (f) {
      var t = f.step === null || f.step === undefined ? sim.first_timestep + sim.num_steps : sim.first_timestep + f.step + 1;
      if (best < 0 || t < best) best = t;
    });
    return best;
  }

  function base64ToBuffer(text) {
    var binary = atob(text.trim());
    var bytes = new Uint8Array(binary.length);
    for (var i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
    return bytes.buffer;
  }

  function loadScene(pos) {
    if (state.cache[pos]) return Promise.resolve(state.cache[pos]);
    var got;
    if (CONFIG.mode === "serve") {
      got = fetch("api/scene/" + pos).then(function (r) {
        if (!r.ok) throw new Error("scene " + pos + ": HTTP " + r.status);
        return r.arrayBuffer();
      });
    } else {
      var el = $("scene-" + pos);
      got = el ? Promise.resolve(base64ToBuffer(el.textContent))
               : Promise.reject(new Error("scene " + pos + " is not embedded in this page"));
    }
    return got.then(function (buffer) {
      var scene = decodeScene(buffer);
      var keys = Object.keys(state.cache);
      if (keys.length >= 8) delete state.cache[keys[0]];  // a few decoded scenes only: memory stays bounded
      state.cache[pos] = scene;
      return scene;
    });
  }

  // ------------------------------------------------------------------ geometry helpers
  function X(s, q) { return q * s.scale; }
  function objValid(s, i, t) { return s.a.obj_valid[i * s.T + t] === 1; }
  function objPose(s, i, t) {
    var j = i * s.T + t;
    return { x: s.a.obj_x[j] * s.scale, y: s.a.obj_y[j] * s.scale, yaw: s.a.obj_yaw[j] * s.meta.yaw_units,
             l: Math.max(s.a.obj_len[j] * s.meta.size_units, 0.3), w: Math.max(s.a.obj_wid[j] * s.meta.size_units, 0.3),
             v: s.a.obj_speed[j] * s.meta.size_units };
  }
  function simPose(s, sim, t) {
    return { x: sim.x[t] * s.scale, y: sim.y[t] * s.scale, yaw: sim.yaw[t] * s.meta.yaw_units,
             l: sim.meta.length, w: sim.meta.width };
  }

  // ------------------------------------------------------------------ view transform
  var canvas = $("map"), ctx = canvas.getContext("2d");
  var chart = $("chart"), cctx = chart.getContext("2d");
  var W = 1, H = 1;

  function resize() {
    var ratio = window.devicePixelRatio || 1;
    var r = canvas.getBoundingClientRect();
    W = Math.max(1, r.width); H = Math.max(1, r.height);
    canvas.width = Math.round(W * ratio); canvas.height = Math.round(H * ratio);
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    var c = chart.getBoundingClientRect();
    chart.width = Math.round(Math.max(1, c.width) * ratio); chart.height = Math.round(Math.max(1, c.height) * ratio);
    cctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  }
  function sx(x) { return (x - state.view.cx) * state.view.k + W / 2; }
  function sy(y) { return H / 2 - (y - state.view.cy) * state.view.k; }
  function wx(px) { return (px - W / 2) / state.view.k + state.view.cx; }
  function wy(py) { return (H / 2 - py) / state.view.k + state.view.cy; }

  function fit() {
    var s = state.scene;
    if (!s || s.meta.error) return;
    var xs = [], ys = [];
    var add = function (x, y) { xs.push(x); ys.push(y); };
    var sdc = s.meta.sdc, t, i;
    if (sdc >= 0) for (t = 0; t < s.T; t++) if (objValid(s, sdc, t)) { var p = objPose(s, sdc, t); add(p.x, p.y); }
    s.sims.forEach(function (sim) { for (t = 0; t < s.T; t++) if (sim.valid[t]) add(sim.x[t] * s.scale, sim.y[t] * s.scale); });
    if (!xs.length) for (i = 0; i < s.N; i++) for (t = 0; t < s.T; t++) if (objValid(s, i, t)) { var q = objPose(s, i, t); add(q.x, q.y); }
    if (!xs.length) for (i = 0; i < s.a.rg_x.length; i++) add(X(s, s.a.rg_x[i]), X(s, s.a.rg_y[i]));
    if (!xs.length) add(0, 0);
    var lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
    for (i = 0; i < xs.length; i++) {
      lo[0] = Math.min(lo[0], xs[i]); lo[1] = Math.min(lo[1], ys[i]); hi[0] = Math.max(hi[0], xs[i]); hi[1] = Math.max(hi[1], ys[i]);
    }
    var half = Math.max(30, Math.max(hi[0] - lo[0], hi[1] - lo[1]) / 2 + 15);
    state.view = { cx: (lo[0] + hi[0]) / 2, cy: (lo[1] + hi[1]) / 2, k: Math.min(W, H) / (2 * half) };
  }

  // ------------------------------------------------------------------ drawing
  function polyline(xs, ys, from, to, close) {
    ctx.beginPath();
    for (var j = from; j < to; j++) {
      var px = sx(xs[j]), py = sy(ys[j]);
      if (j === from) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    }
    if (close) ctx.closePath();
  }

  function roadStyle(type) {  // [layer, stroke, width px, dash, fill]
    if (type >= 1 && type <= 3) return ["lanes", type === 3 ? "#3d7a3d" : "#5f646a", 1, [6, 5], null];
    if (type >= 6 && type <= 8) return ["lines", "#ffffff", type === 8 ? 2.2 : 1.2, type === 6 ? [8, 7] : [], null];
    if (type >= 9 && type <= 13) return ["lines", "#ffd700", type === 10 || type >= 12 ? 2.2 : 1.2,
                                          type === 9 || type === 10 ? [8, 7] : type === 13 ? [8, 3, 2, 3] : [], null];
    if (type === 15 || type === 16) return ["edges", "#111111", 2.2, [], null];
    if (type === 18) return ["crosswalks", "#ffffff", 1, [], "rgba(255,255,255,0.35)"];
    if (type === 19) return ["bumps", "#ff9f1c", 1.2, [], "rgba(255,159,28,0.45)"];
    if (type === 20) return ["crosswalks", "#b9bcc0", 0.8, [], "rgba(185,188,192,0.35)"];
    return [null];
  }

  function drawRoadgraph(s) {
    var a = s.a, xs = new Float64Array(a.rg_x.length), ys = new Float64Array(a.rg_y.length), r;
    for (r = 0; r < xs.length; r++) { xs[r] = a.rg_x[r] * s.scale; ys[r] = a.rg_y[r] * s.scale; }
    var order = [[1, 2, 3, 18, 19, 20], [6, 7, 8, 9, 10, 11, 12, 13], [15, 16], [17]];
    order.forEach(function (group) {
      for (var p = 0; p < a.rg_type.length; p++) {
        var type = a.rg_type[p];
        if (group.indexOf(type) < 0) continue;
        var from = a.rg_start[p], to = a.rg_start[p + 1];
        if (type === 17) {
          if (!state.layers.stops) continue;
          for (var j = from; j < to; j++) {
            ctx.beginPath(); ctx.arc(sx(xs[j]), sy(ys[j]), Math.max(4, 0.8 * state.view.k), 0, 2 * Math.PI);
            ctx.fillStyle = "#d7191c"; ctx.fill(); ctx.lineWidth = 1.2; ctx.strokeStyle = "#ffffff"; ctx.stroke();
          }
          continue;
        }
        var st = roadStyle(type);
        if (!st[0] || !state.layers[st[0]] || to - from < 2) continue;
        polyline(xs, ys, from, to, !!st[4]);
        if (st[4]) { ctx.fillStyle = st[4]; ctx.fill(); }
        ctx.setLineDash(st[3]); ctx.lineWidth = st[2]; ctx.strokeStyle = st[1]; ctx.stroke();
      }
    });
    ctx.setLineDash([]);
  }

  function drawRuns(s, xq, yq, starts, color, width, dash, pick) {
    var xs = [], ys = [];
    for (var r = 0; r < xq.length; r++) { xs.push(xq[r] * s.scale); ys.push(yq[r] * s.scale); }
    for (var p = 0; p + 1 < starts.length; p++) {
      var style = pick ? pick(p) : null;
      if (style === false) continue;
      polyline(xs, ys, starts[p], starts[p + 1], false);
      ctx.setLineDash(style ? style[2] : dash); ctx.lineWidth = style ? style[1] : width;
      ctx.strokeStyle = style ? style[0] : color; ctx.stroke();
    }
    ctx.setLineDash([]);
  }

  function box(p, fill, stroke, lineWidth, dash) {
    var c = Math.cos(p.yaw), si = Math.sin(p.yaw), hl = p.l / 2, hw = p.w / 2;
    var pts = [[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]];
    ctx.beginPath();
    pts.forEach(function (q, j) {
      var x = sx(p.x + q[0] * c - q[1] * si), y = sy(p.y + q[0] * si + q[1] * c);
      if (j === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    });
    ctx.closePath();
    if (fill) { ctx.fillStyle = fill; ctx.fill(); }
    if (stroke) { ctx.setLineDash(dash || []); ctx.lineWidth = lineWidth; ctx.strokeStyle = stroke; ctx.stroke(); ctx.setLineDash([]); }
    ctx.beginPath();  // heading tick: centre to the middle of the front edge
    ctx.moveTo(sx(p.x), sy(p.y)); ctx.lineTo(sx(p.x + hl * c), sy(p.y + hl * si));
    ctx.lineWidth = 1; ctx.strokeStyle = "#111111"; ctx.stroke();
  }

  function trail(getValid, getXY, t, color, width, from) {
    ctx.beginPath();
    var started = false;
    for (var u = Math.max(0, from); u <= t; u++) {
      if (!getValid(u)) { started = false; continue; }
      var q = getXY(u);
      if (!started) { ctx.moveTo(sx(q[0]), sy(q[1])); started = true; } else ctx.lineTo(sx(q[0]), sy(q[1]));
    }
    ctx.lineWidth = width; ctx.strokeStyle = color; ctx.stroke();
  }

  function draw() {
    ctx.clearRect(0, 0, W, H);
    ctx.fillStyle = "#8f9499"; ctx.fillRect(0, 0, W, H);
    var s = state.scene;
    state.drawn = 0; state.sdcPx = null;
    if (!s || s.meta.error) { setStatus(); return; }
    var a = s.a, t = state.t, i;
    ctx.lineCap = "round"; ctx.lineJoin = "round";
    drawRoadgraph(s);
    if (state.layers.agentpaths && a.apath_start.length > 1)
      drawRuns(s, a.apath_x, a.apath_y, a.apath_start, "#d9b3ff", 1.2, [3, 4]);
    if (state.layers.paths && a.path_start.length > 1) {
      var onRoute = s.meta.path_on_route || [];
      drawRuns(s, a.path_x, a.path_y, a.path_start, "#9be7ff", 1.4, [2, 4], function (p) {
        return onRoute[p] ? ["rgba(0,200,255,0.6)", Math.max(3, Math.min(12, 1.0 * state.view.k)), []] : ["#9be7ff", 1.4, [2, 4]];
      });
    }
    if (state.layers.lights) {
      for (var l = 0; l < s.L; l++) {
        var j = l * s.T + t;
        if (!a.tl_valid[j]) continue;
        ctx.beginPath(); ctx.arc(sx(a.tl_x[j] * s.scale), sy(a.tl_y[j] * s.scale), Math.max(4, 0.9 * state.view.k), 0, 2 * Math.PI);
        ctx.fillStyle = LIGHT_COLORS[a.tl_state[j]] || "#c8c8c8"; ctx.fill();
        ctx.lineWidth = 1.2; ctx.strokeStyle = "#000"; ctx.stroke();
      }
    }
    var sdc = s.meta.sdc;
    if (state.layers.sdclog && sdc >= 0) {
      trail(function (u) { return objValid(s, sdc, u); }, function (u) { var p = objPose(s, sdc, u); return [p.x, p.y]; },
            s.T - 1, "rgba(230,0,126,0.35)", 2, 0);
    }
    if (state.layers.trails) {
      for (i = 0; i < s.N; i++) {
        if (!objValid(s, i, t)) continue;
        var col = i === sdc ? SDC_COLOR : OBJECT_COLORS[s.meta.object_types[i]] || "#777";
        (function (row) {
          trail(function (u) { return objValid(s, row, u); }, function (u) { var p = objPose(s, row, u); return [p.x, p.y]; },
                t, col, i === sdc ? 2.4 : 1.4, t - TRAIL_STEPS);
        })(i);
      }
    }
    var ctrl = {};
    (s.meta.controllable || []).forEach(function (r) { ctrl[r] = true; });
    if (state.layers.objects) {
      for (i = 0; i < s.N; i++) {
        if (i === sdc || !objValid(s, i, t)) continue;
        var pose = objPose(s, i, t);
        box(pose, OBJECT_COLORS[s.meta.object_types[i]] || "#777", "#1a1a1a", 0.8);
        if (state.layers.controllable && ctrl[i]) box(pose, null, "#ffffff", 1.4, [4, 3]);
        state.drawn++;
      }
      if (sdc >= 0 && objValid(s, sdc, t) && !(s.sims.length && state.layers.sims)) {
        var ps = objPose(s, sdc, t);
        box(ps, SDC_COLOR, "#000000", 2);
        state.sdcPx = [Math.round(sx(ps.x)), Math.round(sy(ps.y))];
        state.drawn++;
      }
    }
    if (state.layers.sims) {
      s.sims.forEach(function (sim) {
        trail(function (u) { return sim.valid[u] === 1; }, function (u) { return [sim.x[u] * s.scale, sim.y[u] * s.scale]; },
              t, sim.color, 2.2, sim.meta.first_timestep);
        var u = t;
        while (u > 0 && !sim.valid[u]) u--;  // after the episode ends, keep its last pose
        if (!sim.valid[u]) return;
        var failing = sim.failStep >= 0 && u >= sim.failStep;
        box(simPose(s, sim, u), sim.color, failing ? "#ff1f1f" : "#000000", failing ? 3 : 1.6);
        state.drawn++;
      });
      if (s.sims.length && state.layers.objects && sdc >= 0 && objValid(s, sdc, t)) {
        var pl = objPose(s, sdc, t);  // the logged SDC on top, see-through, so a policy on the log shows both
        box(pl, "rgba(230,0,126,0.45)", SDC_COLOR, 2.5);
        state.sdcPx = [Math.round(sx(pl.x)), Math.round(sy(pl.y))];
        state.drawn++;
      }
    }
    drawChart();
    setStatus();
  }

  // ------------------------------------------------------------------ strip chart (rollouts)
  function drawChart() {
    var s = state.scene, box = $("chartbox");
    var show = !!(s && !s.meta.error && s.sims.length);
    if (box.hidden === show) { box.hidden = !show; resize(); }
    if (!show) return;
    var r = chart.getBoundingClientRect(), cw = r.width, ch = r.height;
    cctx.clearRect(0, 0, cw, ch); cctx.fillStyle = "#ffffff"; cctx.fillRect(0, 0, cw, ch);
    var name = state.metric, left = 50, right = 10, top = 24, bottom = 16;
    var px = function (t) { return left + (cw - left - right) * t / Math.max(1, s.T - 1); };
    var lo = Infinity, hi = -Infinity;
    s.sims.forEach(function (sim) {
      var v = sim.metrics[name];
      if (!v) return;
      for (var k = 0; k < v.length; k++) if (sim.stepValid[k] && isFinite(v[k])) { lo = Math.min(lo, v[k]); hi = Math.max(hi, v[k]); }
    });
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-6) { hi = lo + 1; }
    var py = function (v) { return top + (ch - top - bottom) * (1 - (v - lo) / (hi - lo)); };
    cctx.strokeStyle = "#c9ccd1"; cctx.lineWidth = 1; cctx.strokeRect(left, top, cw - left - right, ch - top - bottom);
    cctx.fillStyle = "#5a6068"; cctx.font = "11px sans-serif"; cctx.textAlign = "right";
    cctx.fillText(fmt(hi), left - 4, top + 9); cctx.fillText(fmt(lo), left - 4, ch - bottom);
    s.sims.forEach(function (sim, index) {
      var v = sim.metrics[name], first = sim.meta.first_timestep;
      if (!v) return;
      cctx.beginPath();
      var started = false;
      for (var k = 0; k < v.length; k++) {
        if (!sim.stepValid[k] || !isFinite(v[k])) { started = false; continue; }
        var x = px(first + k + 1), y = py(v[k]);
        if (!started) { cctx.moveTo(x, y); started = true; } else cctx.lineTo(x, y);
      }
      cctx.lineWidth = 2; cctx.strokeStyle = chartColor(sim.color); cctx.stroke();
      var labels = {};  // failures: a red triangle on the time axis, labels joined per step
      (sim.meta.failures || []).forEach(function (f) {
        if (f.step === null || f.step === undefined) return;
        (labels[f.step] = labels[f.step] || []).push(f.label);
      });
      Object.keys(labels).forEach(function (stepKey) {
        var fx = px(first + (+stepKey) + 1), fy = ch - bottom - 4 - 13 * index;
        cctx.beginPath(); cctx.moveTo(fx, ch - bottom); cctx.lineTo(fx - 5, ch - bottom + 9); cctx.lineTo(fx + 5, ch - bottom + 9);
        cctx.closePath(); cctx.fillStyle = "#e8281e"; cctx.fill();
        cctx.fillStyle = "#b3261e"; cctx.textAlign = "left";
        cctx.fillText(sim.meta.name + ": " + labels[stepKey].join(", "), fx + 6, fy);
      });
      var steps = 0;
      for (var q = 0; q < sim.stepValid.length; q++) steps += sim.stepValid[q];
      if (steps < sim.stepValid.length) {  // the episode terminated: shade what follows
        var endX = px(first + steps);
        cctx.fillStyle = "rgba(200,40,30,0.08)"; cctx.fillRect(endX, top, cw - right - endX, ch - top - bottom);
      }
    });
    var cx = px(state.t);
    cctx.beginPath(); cctx.moveTo(cx, top); cctx.lineTo(cx, ch - bottom); cctx.strokeStyle = "#1d2024"; cctx.lineWidth = 1; cctx.stroke();
  }

  function chartColor(color) { return color === "#ffffff" ? "#9a9a9a" : color === "#a6ff00" ? "#5fa800" : color === "#ffe600" ? "#c9a800" : color; }

  function fmt(v) { return Math.abs(v) >= 100 ? v.toFixed(0) : Math.abs(v) >= 1 ? v.toFixed(2) : v.toFixed(3); }

  function fillMetrics() {
    var s = state.scene, select = $("metric");
    if (!s || s.meta.error || !s.sims.length) return;
    var names = [];
    s.sims.forEach(function (sim) { sim.meta.metrics.forEach(function (n) { if (names.indexOf(n) < 0) names.push(n); }); });
    var want = state.metric || PARAMS.get("metric") || "speed";
    if (names.indexOf(want) < 0) want = names[0];
    select.innerHTML = names.map(function (n) { return "<option" + (n === want ? " selected" : "") + ">" + esc(n) + "</option>"; }).join("");
    state.metric = want;
  }

  // ------------------------------------------------------------------ legend, summary, list
  function esc(text) {
    return String(text).replace(/[&<>"']/g, function (c) { return { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]; });
  }

  function legend() {
    var s = state.scene, rows = [];
    var item = function (color, label, extra) { rows.push("<div><i style='background:" + color + (extra || "") + "'></i>" + esc(label) + "</div>"); };
    if (!s || s.meta.error) { $("legend").innerHTML = ""; return; }
    item(SDC_COLOR, s.sims.length ? "logged SDC" : "SDC");
    s.sims.forEach(function (sim) {
      var verdict = sim.meta.failures && sim.meta.failures.length ? " - " + sim.meta.failures[0].label : " - no failure";
      item(sim.color, sim.meta.name + verdict);
    });
    var types = {};
    for (var i = 0; i < s.N; i++) types[s.meta.object_types[i]] = true;
    Object.keys(types).forEach(function (k) { if (OBJECT_COLORS[k]) item(OBJECT_COLORS[k], OBJECT_NAMES[k]); });
    if ((s.meta.path_on_route || []).some(function (x) { return x; })) item("rgba(0,200,255,0.75)", "SDC path on route");
    if ((s.meta.controllable || []).length) item("transparent", "controllable", ";border:1px dashed #fff;background:#555");
    if (s.L) item("#2fd24a", "light go / caution / stop", ";background:linear-gradient(90deg,#2fd24a 33%,#ffd21f 33% 66%,#e8281e 66%)");
    $("legend").innerHTML = rows.join("");
  }

  function summaryHtml(entry) {
    var s = entry.summary, rows = [["id", entry.id], ["file", entry.file + " (record " + entry.record + ")"]];
    var scene = state.scene;
    if (s && s.dataset !== undefined) {
      rows.push(["dataset", s.dataset]);
      rows.push(["objects", s.objects + "  " + Object.keys(s.objects_by_type || {}).map(function (k) { return k + " " + s.objects_by_type[k]; }).join(", ")]);
      rows.push(["traffic lights", s.lights + (s.lights ? "  now: " + Object.keys(s.light_states_now || {}).map(function (k) { return k + " " + s.light_states_now[k]; }).join(", ") : "")]);
      rows.push(["SDC paths", s.paths + " (" + s.on_route_paths + " on route)"]);
      rows.push(["controllable", s.controllable]);
      rows.push(["roadgraph points", s.roadgraph_points]);
      if (s.sdc_speed_mean !== null) rows.push(["SDC speed mean", s.sdc_speed_mean + " m/s"]);
      if (s.sdc_distance_m !== null) rows.push(["SDC distance", s.sdc_distance_m + " m"]);
    } else if (!s) {
      rows.push(["summary", "(computed in the background...)"]);
    }
    if (scene && scene.sims && scene.sims.length && scene.meta.id === entry.id) {
      scene.sims.forEach(function (sim) {
        var e = sim.meta.episode || {};
        var bits = ["accurate", "vmax_score", "progress_ratio"].filter(function (k) { return e[k] !== undefined && e[k] !== null; })
          .map(function (k) { return k + " " + fmt(e[k]); });
        rows.push(["<span style='color:" + chartColor(sim.color) + "'>&#9632;</span> " + esc(sim.meta.name),
                   bits.join(", ") + ((sim.meta.failures || []).length ? "<br><span class='problem'>" +
                   sim.meta.failures.map(function (f) { return esc(f.label) + (f.step === null ? "" : " at step " + (f.step + 1)); }).join("; ") + "</span>" : ""), true]);
      });
    }
    var problems = (s && s.problems) || [];
    var html = "<table>" + rows.map(function (r) { return "<tr><td>" + (r[2] ? r[0] : esc(r[0])) + "</td><td>" + (r[2] ? r[1] : esc(r[1])) + "</td></tr>"; }).join("") + "</table>";
    html += "<div><b>validate:</b> " + (s ? (problems.length ? problems.length + " problem(s)" : "no problems") : "pending") + "</div>";
    html += problems.map(function (p) { return "<div class='problem'>" + esc(p) + "</div>"; }).join("");
    return html;
  }

  function entryText(e) {
    var s = e.summary || {};
    return (e.id + " " + (s.dataset || "") + " " + e.file + " " + (s.problems || []).join(" ")).toLowerCase();
  }

  function renderList() {
    var query = $("search").value.trim().toLowerCase();
    state.filtered = [];
    for (var i = 0; i < state.entries.length; i++)
      if (!query || entryText(state.entries[i]).indexOf(query) >= 0) state.filtered.push(i);
    var shown = state.filtered.slice(0, 2000);
    $("list").innerHTML = shown.map(function (pos) {
      var e = state.entries[pos], s = e.summary;
      var sub = s && s.dataset !== undefined ? esc(s.dataset) + " &middot; " + s.objects + " obj &middot; " + s.lights + " lights &middot; " +
                s.paths + " paths &middot; " + s.controllable + " ctrl" : (s ? "" : "&hellip;");
      var badge = s ? (s.problems && s.problems.length ? "<span class='badge'>" + s.problems.length + "</span>" : "<span class='badge ok'>ok</span>") : "";
      return "<div class='row" + (pos === state.sel ? " sel" : "") + "' data-pos='" + pos + "'><div class='id'>" + esc(e.id) + badge +
             "</div><div class='sub'>" + sub + "</div></div>";
    }).join("") + (state.filtered.length > shown.length ? "<div class='row sub'>" + (state.filtered.length - shown.length) + " more: refine the search</div>" : "");
  }

  function showSummary() {
    $("summary").innerHTML = state.sel >= 0 ? summaryHtml(state.entries[state.sel]) : "";
  }

  function message(text) {
    var el = $("message");
    el.hidden = !text; el.textContent = text || "";
  }

  // ------------------------------------------------------------------ selection and time
  function select(pos, frame) {
    if (pos < 0 || pos >= state.entries.length) return;
    state.sel = pos; state.loading = pos;
    renderList(); showSummary();
    message("loading " + state.entries[pos].id + " ...");
    loadScene(pos).then(function (scene) {
      if (state.loading !== pos) return;
      state.scene = scene;
      if (scene.meta.summary && scene.meta.summary.problems && !state.entries[pos].summary) {
        state.entries[pos].summary = scene.meta.summary; renderList();
      }
      message(scene.meta.error ? "cannot show this record: " + scene.meta.error : "");
      var slider = $("slider");
      slider.max = String(Math.max(0, scene.T - 1));
      var t = frame !== undefined && frame !== null ? frame : (scene.meta.current_step || 0);
      state.t = Math.max(0, Math.min(scene.T - 1, t));
      fillMetrics(); legend(); showSummary();
      resize(); fit();
      var asked = (PARAMS.get("view") || "").split(",").map(parseFloat);  // ?view=x,y,pixels per metre (data frame)
      if (asked.length === 3 && asked.every(isFinite) && !state.viewApplied && !scene.meta.error) {
        state.view = { cx: asked[0] - scene.meta.origin[0], cy: asked[1] - scene.meta.origin[1], k: Math.max(0.01, asked[2]) };
        state.viewApplied = true;
      }
      updateTime();
      var hover = (PARAMS.get("hover") || "").split(",").map(parseFloat);  // ?hover=x,y: the tooltip there (a test hook)
      if (hover.length === 2 && hover.every(isFinite) && !scene.meta.error) {
        var r = canvas.getBoundingClientRect();
        tooltip({ clientX: r.left + sx(hover[0] - scene.meta.origin[0]), clientY: r.top + sy(hover[1] - scene.meta.origin[1]) });
      }
    }).catch(function (err) {
      errors.push(String(err && err.message || err));
      message("cannot load the scene: " + (err && err.message || err));
      setStatus();
    });
  }

  function updateTime() {
    var s = state.scene;
    $("slider").value = String(state.t);
    if (s && !s.meta.error) {
      var seconds = (state.t - (s.meta.current_step || 0)) * (s.meta.dt || 0.1);
      $("stepinfo").textContent = "step " + state.t + " / " + (s.T - 1) + "  (" + (seconds >= 0 ? "+" : "") + seconds.toFixed(1) + " s)";
    }
    draw();
  }

  function step(delta) {
    var s = state.scene;
    if (!s) return;
    state.t = Math.max(0, Math.min(s.T - 1, state.t + delta));
    updateTime();
  }

  function setPlaying(on) {
    state.playing = on;
    $("play").innerHTML = on ? "&#10074;&#10074;" : "&#9654;";
    if (on) {
      if (state.scene && state.t >= state.scene.T - 1) state.t = 0;
      state.lastTick = performance.now(); state.acc = 0;
      requestAnimationFrame(tick);
    }
  }

  function tick(now) {
    if (!state.playing) return;
    state.acc += (now - state.lastTick) * state.speed;
    state.lastTick = now;
    var s = state.scene;
    if (s && state.acc >= 100) {
      var n = Math.floor(state.acc / 100);
      state.acc -= n * 100;
      if (state.t >= s.T - 1) { setPlaying(false); return; }
      step(n);
    }
    requestAnimationFrame(tick);
  }

  function setStatus() {
    var el = $("status"), s = state.scene;
    el.setAttribute("data-ready", s ? "1" : "0");
    el.setAttribute("data-scenario", s ? s.meta.id : "");
    el.setAttribute("data-frame", String(state.t));
    el.setAttribute("data-drawn", String(state.drawn));
    el.setAttribute("data-sdc-px", state.sdcPx ? state.sdcPx.join(",") : "");
    var origin = s && s.meta.origin ? s.meta.origin : [0, 0];  // the view centre in the data's own coordinates
    el.setAttribute("data-view", [(state.view.cx + origin[0]).toFixed(3), (state.view.cy + origin[1]).toFixed(3),
                                  state.view.k.toFixed(5), W, H].join(","));
    var rect = canvas.getBoundingClientRect();
    el.setAttribute("data-canvas", [Math.round(rect.left), Math.round(rect.top), Math.round(rect.width), Math.round(rect.height)].join(","));
    el.setAttribute("data-entries", String(state.entries.length));
    el.setAttribute("data-errors", errors.join(" | "));
  }

  // ------------------------------------------------------------------ hover tooltip
  function hit(px, py) {
    var s = state.scene;
    if (!s || s.meta.error) return null;
    var x = wx(px), y = wy(py), t = state.t, slack = 3 / state.view.k, best = null;
    var inside = function (p) {
      var dx = x - p.x, dy = y - p.y, c = Math.cos(p.yaw), si = Math.sin(p.yaw);
      var lx = dx * c + dy * si, ly = -dx * si + dy * c;
      return Math.abs(lx) <= p.l / 2 + slack && Math.abs(ly) <= p.w / 2 + slack;
    };
    if (state.layers.sims) s.sims.forEach(function (sim) {
      if (sim.valid[t] && inside(simPose(s, sim, t))) best = { sim: sim };
    });
    if (best) return best;
    if (state.layers.objects) for (var i = s.N - 1; i >= 0; i--) {
      if (objValid(s, i, t) && inside(objPose(s, i, t))) {
        if (i === s.meta.sdc) return { row: i };
        best = best || { row: i };
      }
    }
    return best;
  }

  function tooltip(ev) {
    var r = canvas.getBoundingClientRect(), px = ev.clientX - r.left, py = ev.clientY - r.top;
    var found = hit(px, py), tip = $("tooltip"), s = state.scene;
    if (!found) { tip.hidden = true; return; }
    var lines;
    if (found.sim) {
      var t = state.t, sim = found.sim, k = t - sim.meta.first_timestep - 1;
      var sp = sim.metrics.speed && k >= 0 && k < sim.metrics.speed.length ? sim.metrics.speed[k] : null;
      lines = ["simulated SDC: " + sim.meta.name, "size " + sim.meta.length.toFixed(2) + " x " + sim.meta.width.toFixed(2) + " m",
               sp === null ? "" : "speed " + sp.toFixed(2) + " m/s"];
    } else {
      var i = found.row, p = objPose(s, i, state.t);
      lines = ["id " + s.meta.object_ids[i] + (i === s.meta.sdc ? " (SDC)" : ""), "type " + (OBJECT_NAMES[s.meta.object_types[i]] || s.meta.object_types[i]),
               "size " + p.l.toFixed(2) + " x " + p.w.toFixed(2) + " m", "speed " + p.v.toFixed(2) + " m/s"];
      if ((s.meta.controllable || []).indexOf(i) >= 0) lines.push("controllable");
    }
    tip.textContent = lines.filter(Boolean).join("\n");
    tip.hidden = false;
    tip.style.left = Math.min(px + 14, W - 180) + "px"; tip.style.top = Math.min(py + 12, H - 80) + "px";
  }

  // ------------------------------------------------------------------ wiring
  function buildLayers() {
    $("layers").innerHTML = LAYERS.map(function (l) {
      return "<label><input type='checkbox' data-layer='" + l[0] + "'" + (state.layers[l[0]] ? " checked" : "") + "> " + esc(l[1]) + "</label>";
    }).join("");
    $("layers").addEventListener("change", function (ev) {
      var name = ev.target.getAttribute("data-layer");
      if (name) { state.layers[name] = ev.target.checked; draw(); }
    });
  }

  function wire() {
    var drag = null;
    canvas.addEventListener("mousedown", function (ev) { drag = [ev.clientX, ev.clientY]; canvas.classList.add("drag"); });
    window.addEventListener("mouseup", function () { drag = null; canvas.classList.remove("drag"); });
    window.addEventListener("mousemove", function (ev) {
      if (drag) {
        state.view.cx -= (ev.clientX - drag[0]) / state.view.k;
        state.view.cy += (ev.clientY - drag[1]) / state.view.k;
        drag = [ev.clientX, ev.clientY];
        draw();
      }
    });
    canvas.addEventListener("mousemove", tooltip);
    canvas.addEventListener("mouseleave", function () { $("tooltip").hidden = true; });
    canvas.addEventListener("wheel", function (ev) {
      ev.preventDefault();
      var r = canvas.getBoundingClientRect(), px = ev.clientX - r.left, py = ev.clientY - r.top;
      var x = wx(px), y = wy(py);
      state.view.k = Math.max(0.05, Math.min(400, state.view.k * Math.exp(-ev.deltaY * 0.0015)));
      state.view.cx = x - (px - W / 2) / state.view.k;  // keep the point under the cursor fixed
      state.view.cy = y + (py - H / 2) / state.view.k;
      draw();
    }, { passive: false });
    $("slider").addEventListener("input", function () { state.t = parseInt($("slider").value, 10) || 0; updateTime(); });
    $("play").addEventListener("click", function () { setPlaying(!state.playing); });
    $("speed").addEventListener("change", function () { state.speed = parseFloat($("speed").value) || 1; });
    $("fit").addEventListener("click", function () { fit(); draw(); });
    $("metric").addEventListener("change", function () { state.metric = $("metric").value; drawChart(); });
    $("search").addEventListener("input", renderList);
    $("list").addEventListener("click", function (ev) {
      var row = ev.target.closest(".row");
      if (row && row.hasAttribute("data-pos")) select(parseInt(row.getAttribute("data-pos"), 10));
    });
    document.addEventListener("keydown", function (ev) {
      if (ev.target && (ev.target.tagName === "INPUT" && ev.target.type !== "range" || ev.target.tagName === "SELECT")) return;
      if (ev.key === "ArrowRight") { step(ev.shiftKey ? 10 : 1); ev.preventDefault(); }
      else if (ev.key === "ArrowLeft") { step(ev.shiftKey ? -10 : -1); ev.preventDefault(); }
      else if (ev.key === " ") { setPlaying(!state.playing); ev.preventDefault(); }
      else if (ev.key === "f") { fit(); draw(); }
      else if (ev.key === "ArrowDown" || ev.key === "ArrowUp") {
        var at = state.filtered.indexOf(state.sel) + (ev.key === "ArrowDown" ? 1 : -1);
        if (at >= 0 && at < state.filtered.length) select(state.filtered[at]);
        ev.preventDefault();
      }
    });
    window.addEventListener("resize", function () { resize(); draw(); });
  }

  function setNote(text, fileErrors) {
    $("note").innerHTML = esc(text || "") + (fileErrors || []).map(function (e) { return "<div class='err'>" + esc(e) + "</div>"; }).join("");
  }

  function start(entries, note, fileErrors) {
    state.entries = entries;
    setNote(note, fileErrors);
    renderList();
    var wanted = PARAMS.get("scenario"), pos = 0;
    if (wanted !== null) {
      pos = -1;
      for (var i = 0; i < entries.length; i++) if (entries[i].id === wanted) { pos = i; break; }
      if (pos < 0) { message("no scenario with id " + wanted); setStatus(); return; }
    } else if (CONFIG.initial !== null && CONFIG.initial !== undefined) pos = CONFIG.initial;
    var frame = PARAMS.get("frame");
    if (entries.length) select(pos, frame === null ? null : parseInt(frame, 10));
    if (PARAMS.get("play") === "1") setPlaying(true);
  }

  function pollSummaries(since) {
    fetch("api/summaries?since=" + since).then(function (r) { return r.json(); }).then(function (got) {
      Object.keys(got.summaries).forEach(function (pos) {
        var e = state.entries[+pos];
        if (e) e.summary = got.summaries[pos];
      });
      if (Object.keys(got.summaries).length) { renderList(); showSummary(); }
      if (got.done < got.total) setTimeout(function () { pollSummaries(got.done); }, 1000);
    }).catch(function () { /* the server was stopped: keep what we have */ });
  }

  buildLayers();
  wire();
  resize();
  setStatus();
  document.title = CONFIG.title || document.title;
  if (CONFIG.mode === "serve") {
    fetch("api/index").then(function (r) { return r.json(); }).then(function (index) {
      start(index.entries, index.note, index.file_errors);
      pollSummaries(0);
    }).catch(function (err) { errors.push(String(err)); message("cannot reach the viewer server"); setStatus(); });
  } else {
    start(CONFIG.entries || [], CONFIG.note, CONFIG.file_errors);
  }
})();
