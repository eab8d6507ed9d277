/* hpe view: grid, filters, coverage map and detail view over window.HPE_VIEW (rows.js).
 * No framework, no network: data files are scripts, so the page works from file:// and any static host.
 * The filter state lives in the URL hash, e.g. #yaw=90,&c.camera=00_00&f.gimbal_lock=1&sort=-angle&open=12
 *   NAME=LO,HI  numeric range, LO <= value < HI (either side may be empty)
 *   c.NAME=A|B  category values;  f.NAME=1|0  flag;  sort=[-]NAME;  open=ROW (detail of that input row)
 *   ids=1       also write the shown rows' numbers into #ids (tests)
 *   sys=NAME    pitch, yaw, roll (filters, sort, captions, coverage map) in system NAME, one of meta.systems
 *               (hpe view --also-in); default: the labels' own system, meta.angles_system
 */
(function () {
  "use strict";
  var t0 = performance.now();
  var D = window.HPE_VIEW, M = D.meta, N = M.n;
  var num = D.num, cat = D.cat, flag = D.flag;
  var HAS_OTHER = !!M.other;
  var TILE_W = 140, TILE_H = 176;
  var RANGE_MAIN = ["pitch", "yaw", "roll"].concat(HAS_OTHER ? ["angle"] : []);
  var AXIS = ["#e0201b", "#1fa83a", "#1f5fe0"]; // subject's left, forehead to chin, out of the nose
  var rowIndex = null; // input row number -> index, built on demand
  var SYSTEMS = M.systems || [M.angles_system];
  var SYS_KEYS = ["pitch", "yaw", "roll", "other_pitch", "other_yaw", "other_roll"];
  var OWN = {}; SYS_KEYS.forEach(function (k) { if (num[k]) OWN[k] = num[k]; });
  var state = { ranges: {}, cats: {}, flags: {}, sort: "row", desc: false, open: null, ids: false, sys: M.angles_system };
  var sel = new Int32Array(0);

  function $(id) { return document.getElementById(id); }
  function el(tag, attrs, text) {
    var e = document.createElement(tag);
    if (attrs) for (var k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text;
    return e;
  }
  function fmt(v, d) { return v === null || v === undefined ? "-" : Number(v).toFixed(d === undefined ? 1 : d); }

  /* ---------- URL hash <-> state ---------- */
  function parseHash() {
    var s = { ranges: {}, cats: {}, flags: {}, sort: "row", desc: false, open: null, ids: false, sys: M.angles_system };
    var h = location.hash.replace(/^#/, "");
    if (!h) return s;
    h.split("&").forEach(function (part) {
      var i = part.indexOf("="); if (i < 0) return;
      var k = decodeURIComponent(part.slice(0, i)), v = decodeURIComponent(part.slice(i + 1));
      if (k === "sort") { s.desc = v.charAt(0) === "-"; s.sort = v.replace(/^-/, ""); }
      else if (k === "open") s.open = parseInt(v, 10);
      else if (k === "ids") s.ids = v === "1";
      else if (k === "sys") { if (SYSTEMS.indexOf(v) >= 0) s.sys = v; }
      else if (k.indexOf("c.") === 0) s.cats[k.slice(2)] = v.split("|");
      else if (k.indexOf("f.") === 0) s.flags[k.slice(2)] = v === "1" ? 1 : 0;
      else if (num[k]) {
        var lh = v.split(",");
        var lo = lh[0] === "" ? null : parseFloat(lh[0]), hi = lh.length > 1 && lh[1] !== "" ? parseFloat(lh[1]) : null;
        if (lo !== null || hi !== null) s.ranges[k] = [lo, hi];
      }
    });
    if (!num[s.sort] && !cat[s.sort]) s.sort = "row";
    return s;
  }
  function writeHash() {
    var parts = [];
    Object.keys(state.ranges).forEach(function (k) {
      var r = state.ranges[k];
      parts.push(encodeURIComponent(k) + "=" + (r[0] === null ? "" : r[0]) + "," + (r[1] === null ? "" : r[1]));
    });
    Object.keys(state.cats).forEach(function (k) {
      parts.push("c." + encodeURIComponent(k) + "=" + state.cats[k].map(encodeURIComponent).join("|"));
    });
    Object.keys(state.flags).forEach(function (k) { parts.push("f." + encodeURIComponent(k) + "=" + state.flags[k]); });
    if (state.sort !== "row" || state.desc) parts.push("sort=" + (state.desc ? "-" : "") + encodeURIComponent(state.sort));
    if (state.open !== null) parts.push("open=" + state.open);
    if (state.sys !== M.angles_system) parts.push("sys=" + encodeURIComponent(state.sys));
    if (state.ids) parts.push("ids=1");
    var h = parts.length ? "#" + parts.join("&") : "";
    if (h !== location.hash && !(h === "" && location.hash === "")) history.replaceState(null, "", h || location.pathname + location.search);
  }

  /* ---------- the system the angles are in ---------- */
  function useSystem(name) {
    var src = name === M.angles_system ? OWN : D.systems[name];
    if (!src) { name = M.angles_system; src = OWN; }
    SYS_KEYS.forEach(function (k) { if (src[k]) num[k] = src[k]; });
    state.sys = name;
    pool.forEach(function (t) { t.removeAttribute("data-i"); }); // captions change: redraw every tile
    var s = $("system"); if (s) s.value = name;
    document.body.setAttribute("data-system", name);
  }

  /* ---------- filtering and sorting ---------- */
  function passes(skipCell) {
    var keep = new Uint8Array(N).fill(1);
    Object.keys(state.ranges).forEach(function (k) {
      if (skipCell && (k === "yaw" || k === "pitch")) return;
      var a = num[k], lo = state.ranges[k][0], hi = state.ranges[k][1];
      for (var i = 0; i < N; i++) {
        if (!keep[i]) continue;
        var v = a[i];
        if (v === null || (lo !== null && v < lo) || (hi !== null && v >= hi)) keep[i] = 0;
      }
    });
    Object.keys(state.cats).forEach(function (k) {
      var c = cat[k]; if (!c) return;
      var want = new Uint8Array(c.values.length + 1);
      state.cats[k].forEach(function (v) { var j = c.values.indexOf(v); if (j >= 0) want[j] = 1; });
      for (var i = 0; i < N; i++) if (keep[i] && (c.codes[i] < 0 || !want[c.codes[i]])) keep[i] = 0;
    });
    Object.keys(state.flags).forEach(function (k) {
      var f = flag[k]; if (!f) return;
      var w = state.flags[k];
      for (var i = 0; i < N; i++) if (keep[i] && f[i] !== w) keep[i] = 0;
    });
    return keep;
  }
  function apply() {
    var keep = passes(false), n = 0, i;
    for (i = 0; i < N; i++) n += keep[i];
    var out = new Int32Array(n), j = 0;
    for (i = 0; i < N; i++) if (keep[i]) out[j++] = i;
    var key = num[state.sort], c = cat[state.sort];
    if (state.sort !== "row" && (key || c)) {
      var vals = new Float64Array(N);
      if (key) for (i = 0; i < N; i++) vals[i] = key[i] === null ? NaN : key[i];
      else for (i = 0; i < N; i++) vals[i] = c.codes[i] < 0 ? NaN : c.codes[i];
      var sgn = state.desc ? -1 : 1;
      out.sort(function (a, b) {
        var x = vals[a], y = vals[b];
        if (x !== x) return y !== y ? a - b : 1; // missing values last
        if (y !== y) return -1;
        return x === y ? a - b : sgn * (x - y);
      });
    } else if (state.desc) out.reverse();
    sel = out;
    var rej = 0, st = cat.status, okCode = st.values.indexOf("ok");
    for (i = 0; i < N; i++) if (st.codes[i] !== okCode) rej++;
    $("counts").textContent = "showing " + sel.length.toLocaleString("en") + " of " + N.toLocaleString("en") +
      " rows" + (rej ? " (" + rej.toLocaleString("en") + " without a picture)" : "");
    if (state.ids) {
      var ids = new Array(sel.length);
      for (i = 0; i < sel.length; i++) ids[i] = num.row[sel[i]];
      $("ids").textContent = JSON.stringify(ids);
    }
    $("grid").scrollTop = 0;
    layout();
    drawCoverage();
    writeHash();
    document.body.setAttribute("data-shown", String(sel.length));
  }

  /* ---------- virtualised grid ---------- */
  var pool = [], cols = 1, decoded = 0, broken = 0;
  function tileFor(k) {
    while (pool.length <= k) {
      var t = el("div", { "class": "tile" });
      t.appendChild(el("img", { alt: "" }));
      t.appendChild(el("div", { "class": "none" }));
      t.appendChild(el("div", { "class": "cap" }));
      t.addEventListener("click", function () { openDetail(parseInt(this.getAttribute("data-i"), 10)); });
      var img = t.firstChild;
      img.addEventListener("load", function () { decoded++; document.body.setAttribute("data-decoded", decoded); });
      img.addEventListener("error", function () {
        broken++; document.body.setAttribute("data-broken", broken);
        window.HPE_ERRORS.push("image failed: " + this.getAttribute("src"));
      });
      $("spacer").appendChild(t);
      pool.push(t);
    }
    return pool[k];
  }
  function caption(i) {
    var s = "y " + fmt(num.yaw[i]) + " p " + fmt(num.pitch[i]) + " r " + fmt(num.roll[i]);
    return s;
  }
  function layout() {
    var g = $("grid");
    cols = Math.max(1, Math.floor((g.clientWidth - 8) / TILE_W));
    var rows = Math.ceil(sel.length / cols);
    $("spacer").style.height = rows * TILE_H + "px";
    render();
  }
  function render() {
    var g = $("grid");
    var first = Math.max(0, Math.floor(g.scrollTop / TILE_H) - 1) * cols;
    var last = Math.min(sel.length, (Math.ceil((g.scrollTop + g.clientHeight) / TILE_H) + 1) * cols);
    var k = 0;
    for (var p = first; p < last; p++, k++) {
      var i = sel[p], t = tileFor(k);
      t.style.display = "";
      t.style.left = (p % cols) * TILE_W + 4 + "px";
      t.style.top = Math.floor(p / cols) * TILE_H + "px";
      if (t.getAttribute("data-i") === String(i)) continue;
      t.setAttribute("data-i", i);
      var img = t.childNodes[0], none = t.childNodes[1], cap = t.childNodes[2];
      var th = D.thumb[i];
      if (th) {
        img.style.display = ""; none.style.display = "none";
        img.setAttribute("src", "thumbs/" + th);
      } else {
        img.style.display = "none"; img.removeAttribute("src"); none.style.display = "";
        none.textContent = cat.status.values[cat.status.codes[i]];
      }
      cap.textContent = "";
      cap.appendChild(document.createTextNode(caption(i)));
      cap.appendChild(el("br"));
      cap.appendChild(document.createTextNode((M.labels.unit === "file" ? "#" : M.labels.unit + " ") + num.row[i] + " "));
      if (HAS_OTHER) cap.appendChild(el("b", null, num.angle[i] === null ? "" : fmt(num.angle[i]) + "\u00b0 apart"));
      t.title = caption(i) + (HAS_OTHER ? "; " + fmt(num.angle[i]) + " deg between the poses" : "");
    }
    for (; k < pool.length; k++) pool[k].style.display = "none";
  }

  /* ---------- coverage map: yaw x pitch, 10-degree cells ---------- */
  var COV = { yaw0: -180, pitch0: -180, step: 10, nx: 36, ny: 36, px: 8 };
  function drawCoverage() {
    var cv = $("coverage"); if (!cv) return;
    var keep = passes(true), cnt = new Int32Array(COV.nx * COV.ny), max = 0, y = num.yaw, p = num.pitch;
    for (var i = 0; i < N; i++) {
      if (!keep[i] || y[i] === null || p[i] === null) continue;
      var cx = Math.floor((y[i] - COV.yaw0) / COV.step), cy = Math.floor((p[i] - COV.pitch0) / COV.step);
      if (cx < 0 || cy < 0 || cx >= COV.nx || cy >= COV.ny) continue;
      var c = ++cnt[cy * COV.nx + cx]; if (c > max) max = c;
    }
    COV.cnt = cnt;
    var ctx = cv.getContext("2d"), s = COV.px;
    ctx.fillStyle = "#f4f5f7"; ctx.fillRect(0, 0, cv.width, cv.height);
    for (var yy = 0; yy < COV.ny; yy++) for (var xx = 0; xx < COV.nx; xx++) {
      var n = cnt[yy * COV.nx + xx]; if (!n) continue;
      var a = Math.log(1 + n) / Math.log(1 + max);
      ctx.fillStyle = "rgba(31,95,224," + (0.15 + 0.85 * a).toFixed(3) + ")";
      ctx.fillRect(xx * s, (COV.ny - 1 - yy) * s, s - 1, s - 1); // pitch up is up
    }
    ctx.strokeStyle = "#999"; ctx.beginPath();
    ctx.moveTo(COV.nx / 2 * s, 0); ctx.lineTo(COV.nx / 2 * s, cv.height);
    ctx.moveTo(0, COV.ny / 2 * s); ctx.lineTo(cv.width, COV.ny / 2 * s); ctx.stroke();
    var ry = state.ranges.yaw, rp = state.ranges.pitch;
    if (ry && rp && ry[0] !== null && rp[0] !== null) {
      ctx.strokeStyle = "#c2410c"; ctx.lineWidth = 2;
      ctx.strokeRect((ry[0] - COV.yaw0) / COV.step * s, (COV.ny - (rp[0] - COV.pitch0) / COV.step - 1) * s, s, s);
      ctx.lineWidth = 1;
    }
  }
  function coverageCell(ev) {
    var cv = $("coverage"), r = cv.getBoundingClientRect();
    var x = Math.floor((ev.clientX - r.left) / r.width * COV.nx), yy = COV.ny - 1 - Math.floor((ev.clientY - r.top) / r.height * COV.ny);
    return [Math.max(0, Math.min(COV.nx - 1, x)), Math.max(0, Math.min(COV.ny - 1, yy))];
  }

  /* ---------- filter panel ---------- */
  function rangeRow(k, label) {
    var row = el("div", { "class": "range" });
    row.appendChild(el("label", { title: k }, label || k));
    ["min", "max"].forEach(function (w, j) {
      var inp = el("input", { type: "number", step: "any", placeholder: w, "data-k": k, "data-j": j });
      inp.addEventListener("change", function () {
        var r = state.ranges[k] || [null, null], v = this.value === "" ? null : parseFloat(this.value);
        r[j] = v; if (r[0] === null && r[1] === null) delete state.ranges[k]; else state.ranges[k] = r;
        apply();
      });
      row.appendChild(inp);
    });
    return row;
  }
  function syncInputs() {
    Array.prototype.forEach.call(document.querySelectorAll("#filters input[data-k]"), function (inp) {
      var r = state.ranges[inp.getAttribute("data-k")], v = r ? r[+inp.getAttribute("data-j")] : null;
      inp.value = v === null || v === undefined ? "" : v;
    });
    Array.prototype.forEach.call(document.querySelectorAll("#filters select[data-cat]"), function (s) {
      var want = state.cats[s.getAttribute("data-cat")] || [];
      Array.prototype.forEach.call(s.options, function (o) { o.selected = want.indexOf(o.value) >= 0; });
    });
    Array.prototype.forEach.call(document.querySelectorAll("#filters select[data-flag]"), function (s) {
      var v = state.flags[s.getAttribute("data-flag")]; s.value = v === undefined ? "" : String(v);
    });
    var so = $("sort"); if (so) so.value = state.sort; var de = $("desc"); if (de) de.checked = state.desc;
  }
  function buildFilters() {
    var f = $("filters");
    var head = el("h3", { id: "angles-head" }, "Angles (");
    if (SYSTEMS.length > 1) {
      var ss = el("select", { id: "system", title: "the system of pitch, yaw and roll: filters, sort, captions and the coverage map" });
      SYSTEMS.forEach(function (k) { ss.appendChild(el("option", { value: k }, k)); });
      ss.addEventListener("change", function () { useSystem(this.value); apply(); });
      head.appendChild(ss);
    } else head.appendChild(document.createTextNode(M.angles_system));
    head.appendChild(document.createTextNode(", degrees)"));
    f.appendChild(head);
    RANGE_MAIN.forEach(function (k) {
      f.appendChild(rangeRow(k, k === "angle" ? "angle apart" : k));
    });
    f.appendChild(el("h3", null, "Coverage: yaw (across) x pitch (up)"));
    var cv = el("canvas", { id: "coverage", width: COV.nx * COV.px, height: COV.ny * COV.px,
      title: "click a cell to show its rows; click it again to clear" });
    cv.addEventListener("click", function (ev) {
      var c = coverageCell(ev), y0 = COV.yaw0 + c[0] * COV.step, p0 = COV.pitch0 + c[1] * COV.step;
      var ry = state.ranges.yaw, rp = state.ranges.pitch;
      if (ry && rp && ry[0] === y0 && rp[0] === p0 && ry[1] === y0 + COV.step && rp[1] === p0 + COV.step) {
        delete state.ranges.yaw; delete state.ranges.pitch;
      } else { state.ranges.yaw = [y0, y0 + COV.step]; state.ranges.pitch = [p0, p0 + COV.step]; }
      syncInputs(); apply();
    });
    cv.addEventListener("mousemove", function (ev) {
      var c = coverageCell(ev), y0 = COV.yaw0 + c[0] * COV.step, p0 = COV.pitch0 + c[1] * COV.step;
      this.title = "yaw [" + y0 + ", " + (y0 + COV.step) + "), pitch [" + p0 + ", " + (p0 + COV.step) + "): " +
        (COV.cnt ? COV.cnt[c[1] * COV.nx + c[0]] : 0) + " rows";
    });
    f.appendChild(cv);
    f.appendChild(el("div", { id: "cov-note" }, "yaw -180..180 across, pitch -180..180 up, 10-degree cells; they count the rows the other filters keep"));
    var cats = Object.keys(cat);
    if (cats.length) f.appendChild(el("h3", null, "Categories"));
    cats.forEach(function (k) {
      var c = cat[k], counts = new Int32Array(c.values.length);
      for (var i = 0; i < N; i++) if (c.codes[i] >= 0) counts[c.codes[i]]++;
      f.appendChild(el("div", null, k + (k === "status" ? " (ok, or why a row has no picture)" : "")));
      var s = el("select", { multiple: "", size: String(Math.min(5, Math.max(2, c.values.length))), "data-cat": k });
      c.values.forEach(function (v, j) { var o = el("option", { value: v }, v + " (" + counts[j] + ")"); s.appendChild(o); });
      s.addEventListener("change", function () {
        var vals = Array.prototype.filter.call(this.options, function (o) { return o.selected; }).map(function (o) { return o.value; });
        if (vals.length) state.cats[k] = vals; else delete state.cats[k];
        apply();
      });
      f.appendChild(s);
    });
    var flags = Object.keys(flag);
    if (flags.length) f.appendChild(el("h3", null, "Flags"));
    flags.forEach(function (k) {
      var row = el("div", { "class": "row" });
      row.appendChild(el("label", null, k));
      var s = el("select", { "data-flag": k });
      [["", "any"], ["1", "yes"], ["0", "no"]].forEach(function (o) { s.appendChild(el("option", { value: o[0] }, o[1])); });
      s.addEventListener("change", function () {
        if (this.value === "") delete state.flags[k]; else state.flags[k] = parseInt(this.value, 10);
        apply();
      });
      row.appendChild(s); f.appendChild(row);
    });
    f.appendChild(el("h3", null, "Sort"));
    var row = el("div", { "class": "row" });
    var so = el("select", { id: "sort" });
    ["row"].concat(Object.keys(num).filter(function (k) { return k !== "row"; }), Object.keys(cat)).forEach(function (k) {
      so.appendChild(el("option", { value: k }, k === "row" ? "file order" : k));
    });
    so.addEventListener("change", function () { state.sort = this.value; apply(); });
    var de = el("input", { type: "checkbox", id: "desc" });
    de.addEventListener("change", function () { state.desc = this.checked; apply(); });
    row.appendChild(so); row.appendChild(de); row.appendChild(el("label", { "for": "desc" }, "descending"));
    f.appendChild(row);
    var more = el("details");
    more.appendChild(el("summary", null, "Ranges of other columns"));
    Object.keys(num).forEach(function (k) { if (RANGE_MAIN.indexOf(k) < 0) more.appendChild(rangeRow(k)); });
    f.appendChild(more);
    var reset = el("button", null, "Clear filters");
    reset.addEventListener("click", function () {
      state.ranges = {}; state.cats = {}; state.flags = {}; syncInputs(); apply();
    });
    f.appendChild(el("h3", null, ""));
    f.appendChild(reset);
    var src = el("div", { "class": "src" });
    src.textContent = "labels: " + M.labels.path + " (" + M.labels.system + ")" +
      (HAS_OTHER ? "\nother: " + M.other.path + " (" + M.other.system + ")" : "");
    src.style.whiteSpace = "pre-wrap";
    f.appendChild(src);
  }
  function legend() {
    var l = $("legend");
    function sample(dash, text) {
      var s = document.createElementNS("http://www.w3.org/2000/svg", "svg");
      s.setAttribute("width", "42"); s.setAttribute("height", "12");
      AXIS.forEach(function (c, j) {
        var ln = document.createElementNS("http://www.w3.org/2000/svg", "line");
        ln.setAttribute("x1", 2 + j * 14); ln.setAttribute("x2", 12 + j * 14); ln.setAttribute("y1", 6); ln.setAttribute("y2", 6);
        ln.setAttribute("stroke", c); ln.setAttribute("stroke-width", dash ? 1.5 : 3);
        if (dash) ln.setAttribute("stroke-dasharray", "3 2");
        s.appendChild(ln);
      });
      var span = el("span"); span.appendChild(s); span.appendChild(document.createTextNode(" " + text)); l.appendChild(span);
    }
    sample(false, "labels");
    if (HAS_OTHER) sample(true, "other (dashed)");
    l.appendChild(el("span", null, "red: subject's left, green: forehead to chin, blue: out of the nose"));
  }

  /* ---------- one row in full ---------- */
  var chunks = {}, waiting = {};
  window.HPE_VIEW_ROWS = function (k, d) { chunks[k] = d; (waiting[k] || []).forEach(function (f) { f(d); }); delete waiting[k]; };
  function withChunk(k, f) {
    if (chunks[k]) return f(chunks[k]);
    if (waiting[k]) { waiting[k].push(f); return; }
    waiting[k] = [f];
    var s = document.createElement("script");
    s.src = "rows/" + ("0000" + k).slice(-5) + ".js";
    document.head.appendChild(s);
  }
  function svgEl(tag, attrs) {
    var e = document.createElementNS("http://www.w3.org/2000/svg", tag);
    for (var k in attrs) e.setAttribute(k, attrs[k]);
    return e;
  }
  function indexOfRow(r) {
    if (!rowIndex) { rowIndex = {}; for (var i = 0; i < N; i++) rowIndex[num.row[i]] = i; }
    return rowIndex[r];
  }
  function openDetail(i) {
    state.open = num.row[i]; writeHash();
    var k = Math.floor(i / M.chunk);
    withChunk(k, function (d) { showDetail(i, d, i - k * M.chunk); });
  }
  function showDetail(i, d, j) {
    var body = $("detail-body"); body.textContent = "";
    var im = D.images[D.img[i]] || null;
    var frame = el("div", { "class": "frame" });
    if (im && im.f && D.thumb[i]) {
      frame.appendChild(el("img", { src: "frames/" + im.f, alt: "full frame", id: "detail-img" }));
      var svg = svgEl("svg", { viewBox: "-0.5 -0.5 " + im.w + " " + im.h, preserveAspectRatio: "none" });
      var sw = Math.max(1.5, Math.max(im.w, im.h) / 400);
      var b = d.box[j];
      if (b && b[0] !== null && b[2] !== null) svg.appendChild(svgEl("rect", { x: b[0], y: b[1], width: b[2], height: b[3],
        fill: "none", stroke: "#ffd400", "stroke-width": sw }));
      var lm = d.lm ? d.lm[j] : null;
      if (lm) for (var q = 0; q + 1 < lm.length; q += 2) if (lm[q] !== null && lm[q + 1] !== null)
        svg.appendChild(svgEl("circle", { cx: lm[q], cy: lm[q + 1], r: sw * 1.2, fill: "#00e5ff" }));
      var c = d.centre[j], L = d.length[j];
      function axes(v, dashed) {
        if (!v || v[0] === null || !c || c[0] === null || L === null) return;
        for (var a = 0; a < 3; a++) {
          var attrs = { x1: c[0], y1: c[1], x2: c[0] + L * v[2 * a], y2: c[1] + L * v[2 * a + 1], stroke: AXIS[a],
            "stroke-width": dashed ? sw : 2 * sw, "stroke-linecap": "round" };
          if (dashed) attrs["stroke-dasharray"] = 4 * sw + " " + 3 * sw;
          svg.appendChild(svgEl("line", attrs));
        }
      }
      axes(d.vec[j], false);
      if (HAS_OTHER) axes(d.vec_other[j], true);
      frame.appendChild(svg);
    } else if (D.thumb[i]) { // made with --no-frames: the thumbnail, larger
      frame.appendChild(el("img", { src: "thumbs/" + D.thumb[i], alt: "thumbnail", id: "detail-img",
        style: "width:384px;height:384px;image-rendering:auto" }));
      frame.appendChild(el("p", null, "no full frame (the page was made with --no-frames)"));
    } else {
      frame.appendChild(el("p", null, "no picture: " + cat.status.values[cat.status.codes[i]]));
    }
    body.appendChild(frame);
    var box = el("div", { "class": "cols" });
    box.appendChild(el("div", { "class": "src", id: "detail-src" }, d.src[j]));
    if (HAS_OTHER) {
      box.appendChild(el("div", { "class": "src", id: "detail-other-src" }, d.other_src[j] ? "other: " + d.other_src[j] : "other: no row with this key"));
      box.appendChild(el("div", null, "angle between the two poses: " + fmt(num.angle[i], 3) + " deg"));
    }
    var tab = el("table"), add = function (k, v) {
      var tr = el("tr"); tr.appendChild(el("td", null, k)); tr.appendChild(el("td", null, v === null || v === undefined ? "" : String(v)));
      tab.appendChild(tr);
    };
    add("angles (" + state.sys + ")", "pitch " + fmt(num.pitch[i], 3) + ", yaw " + fmt(num.yaw[i], 3) + ", roll " + fmt(num.roll[i], 3));
    if (HAS_OTHER) add("other in " + state.sys, "pitch " + fmt(num.other_pitch[i], 3) + ", yaw " + fmt(num.other_yaw[i], 3) + ", roll " + fmt(num.other_roll[i], 3));
    add("status", cat.status.values[cat.status.codes[i]]);
    d.cols.forEach(function (k) { add(k, d.values[k][j]); });
    if (HAS_OTHER) d.other_cols.forEach(function (k) { add("other: " + k, d.other_values[k][j]); });
    box.appendChild(tab);
    body.appendChild(box);
    $("detail").hidden = false;
    document.body.setAttribute("data-open", String(num.row[i]));
  }
  function closeDetail() { $("detail").hidden = true; state.open = null; writeHash(); }

  /* ---------- start ---------- */
  state = parseHash();
  legend();
  buildFilters();
  useSystem(state.sys);
  syncInputs();
  apply();
  $("grid").addEventListener("scroll", function () { window.requestAnimationFrame(render); }, { passive: true });
  window.addEventListener("resize", layout);
  $("detail-close").addEventListener("click", closeDetail);
  $("detail").addEventListener("click", function (ev) { if (ev.target === this) closeDetail(); });
  document.addEventListener("keydown", function (ev) { if (ev.key === "Escape") closeDetail(); });
  window.addEventListener("hashchange", function () {
    var s = parseHash(), open = s.open; state = s; useSystem(s.sys); syncInputs(); apply();
    if (open !== null && indexOfRow(open) !== undefined) openDetail(indexOfRow(open));
  });
  if (state.open !== null && indexOfRow(state.open) !== undefined) openDetail(indexOfRow(state.open));
  document.body.setAttribute("data-ready-ms", String(Math.round(performance.now())));
  document.body.setAttribute("data-build-ms", String(Math.round(performance.now() - t0)));
})();
