/* sweep3d report, explorer: each parameter is a heat-map axis, a slider (one value) or pooled.
   The heat map (accuracy and count per cell) is computed here from the rows in
   #explorer-data; clicking a cell shows its images, wrong ones first. */
(function () {
  'use strict';

  var S = window.sweep3d;
  var source = document.getElementById('explorer-data');
  if (!source) {
    S.whenDrawn([]);
    return;
  }
  var data = JSON.parse(source.textContent);
  var params = data.params;
  var N = data.outcome.length;
  var OUTCOMES = ['wrong', 'correct', 'invalid'];
  var INVALID = 2;
  var ROLES = [['x', 'x axis'], ['y', 'y axis'], ['slider', 'slider'], ['pooled', 'pooled']];
  var MAX_CELL_TEXT = 400; // cells beyond which the numbers are left to the hover

  var state = {
    role: params.map(function () { return 'pooled'; }),
    slider: params.map(function () { return 0; }),
    cell: null, // {x: level, y: level} of the clicked cell
  };
  if (data.defaults.x >= 0) state.role[data.defaults.x] = 'x';
  if (data.defaults.y >= 0) state.role[data.defaults.y] = 'y';

  var plot = document.getElementById('explorer-plot');
  var status = document.getElementById('explorer-status');
  var gallery = document.getElementById('explorer-gallery');
  var widgets = params.map(buildControl);
  var clickBound = false;
  var timings = {};
  S.explorer = {state: state, timings: timings};

  /* One parameter's box: its name, a role menu and (as a slider) a range input. */
  function buildControl(param, p) {
    var box = document.createElement('div');
    box.className = 'explorer-control';
    box.dataset.param = param.name;
    var name = document.createElement('span');
    name.className = 'name';
    name.textContent = param.name + (param.binned ? ' (binned)' : '') + ' · ' + param.labels.length +
      (param.labels.length === 1 ? ' value' : ' values');
    var select = document.createElement('select');
    select.setAttribute('aria-label', 'role of ' + param.name);
    ROLES.forEach(function (role) {
      var option = document.createElement('option');
      option.value = role[0];
      option.textContent = role[1];
      select.appendChild(option);
    });
    var range = document.createElement('input');
    range.type = 'range';
    range.min = '0';
    range.max = String(param.labels.length - 1);
    range.step = '1';
    range.setAttribute('aria-label', 'value of ' + param.name);
    var output = document.createElement('output');
    select.addEventListener('change', function () { setRole(p, select.value); });
    range.addEventListener('input', function () { setSlider(p, Number(range.value)); });
    box.append(name, select, range, output);
    document.getElementById('explorer-controls').appendChild(box);
    return {box: box, select: select, range: range, output: output};
  }

  function syncControls() {
    widgets.forEach(function (w, p) {
      var role = state.role[p];
      w.select.value = role;
      w.box.className = 'explorer-control ' + role;
      w.range.hidden = w.output.hidden = role !== 'slider';
      w.range.value = String(state.slider[p]);
      w.output.textContent = params[p].labels[state.slider[p]];
    });
  }

  /* Give parameter p a role; an axis it takes from another parameter is swapped or pooled. */
  function setRole(p, role) {
    var old = state.role[p];
    if (role === 'x' || role === 'y') {
      var holder = state.role.indexOf(role);
      if (holder >= 0 && holder !== p) state.role[holder] = old === 'x' || old === 'y' ? old : 'pooled';
    }
    state.role[p] = role;
    state.cell = null;
    syncControls();
    showGallery();
    return render();
  }

  function setSlider(p, level) {
    state.slider[p] = level;
    syncControls();
    showGallery();
    return render();
  }

  function axis(role) {
    var p = state.role.indexOf(role);
    return {p: p, n: p >= 0 ? params[p].labels.length : 1,
            labels: p >= 0 ? params[p].labels : ['all'], name: p >= 0 ? params[p].name : ''};
  }

  function sliders() {
    var out = [];
    state.role.forEach(function (role, p) { if (role === 'slider') out.push(p); });
    return out;
  }

  function matchesSliders(i, active) {
    for (var s = 0; s < active.length; s++) {
      if (data.level[active[s]][i] !== state.slider[active[s]]) return false;
    }
    return true;
  }

  function levelOf(ax, i) {
    return ax.p >= 0 ? data.level[ax.p][i] : 0;
  }

  /* Valid results and correct ones per cell, row-major (y, x). */
  function tally(x, y) {
    var n = new Int32Array(x.n * y.n), k = new Int32Array(x.n * y.n), active = sliders();
    for (var i = 0; i < N; i++) {
      if (data.outcome[i] === INVALID || !matchesSliders(i, active)) continue;
      var cx = levelOf(x, i), cy = levelOf(y, i);
      if (cx < 0 || cy < 0) continue;
      n[cy * x.n + cx] += 1;
      k[cy * x.n + cx] += data.outcome[i];
    }
    return {n: n, k: k};
  }

  function render() {
    var x = axis('x'), y = axis('y'), counts = tally(x, y);
    var z = [], text = [], hover = [], total = 0, correct = 0;
    for (var cy = 0; cy < y.n; cy++) {
      z.push([]); text.push([]); hover.push([]);
      for (var cx = 0; cx < x.n; cx++) {
        var n = counts.n[cy * x.n + cx], k = counts.k[cy * x.n + cx], ci = S.wilson(k, n);
        total += n; correct += k;
        z[cy].push(n ? k / n : null);
        text[cy].push(n ? S.percent(k / n, 0) + '<br>n=' + n : '');
        hover[cy].push(S.plotText(x.labels[cx]) + ' · ' + S.plotText(y.labels[cy]) + '<br>' +
          (n ? 'accuracy ' + S.percent(k / n) + ' (95% CI ' + S.percent(ci[0], 0) + '–' + S.percent(ci[1], 0) +
               ')<br>' + k + ' of ' + n + ' correct' : 'no results'));
      }
    }
    var ci = S.wilson(correct, total);
    status.textContent = total + ' valid results match the sliders · accuracy ' + S.percent(correct / total) +
      (total ? ' (95% CI ' + S.percent(ci[0], 0) + '–' + S.percent(ci[1], 0) + ')' : '');
    var trace = {
      type: 'heatmap', z: z, x: range(x.n), y: range(y.n), zmin: 0, zmax: 1, colorscale: data.colorscale,
      text: text, texttemplate: x.n * y.n <= MAX_CELL_TEXT ? '%{text}' : '', hovertext: hover,
      hovertemplate: '%{hovertext}<extra></extra>', xgap: 2, ygap: 2,
      colorbar: {tickformat: '.0%', title: {text: 'accuracy'}},
    };
    var shapes = state.cell ? [{type: 'rect', x0: state.cell.x - 0.5, x1: state.cell.x + 0.5,
                                y0: state.cell.y - 0.5, y1: state.cell.y + 0.5,
                                line: {color: '#1f2328', width: 3}}] : [];
    var layout = Object.assign({}, data.layout, {
      height: Math.min(900, Math.max(300, 120 + 34 * y.n)), shapes: shapes,
      xaxis: axisLayout(x, false), yaxis: axisLayout(y, true),
    });
    return S.draw(plot, {data: [trace], layout: layout}).then(function () {
      if (!clickBound) {
        plot.on('plotly_click', onClick);
        clickBound = true;
      }
    });
  }

  function axisLayout(ax, vertical) {
    return {tickmode: 'array', tickvals: range(ax.n), ticktext: ax.labels.map(S.plotText), automargin: true,
            title: {text: S.plotText(ax.name)}, range: vertical ? [ax.n - 0.5, -0.5] : [-0.5, ax.n - 0.5],
            showgrid: false, zeroline: false};
  }

  function onClick(event) {
    var started = performance.now();
    var point = event.points[0];
    state.cell = {x: Math.round(point.x), y: Math.round(point.y)};
    showGallery();
    render().then(function () { timings.click = performance.now() - started; });
  }

  /* The clicked cell's images under the current sliders: wrong first, highest loss first. */
  function showGallery() {
    gallery.replaceChildren();
    if (!state.cell) {
      var hint = document.createElement('p');
      hint.className = 'note';
      hint.textContent = 'Click a cell of the heat map to see its images.';
      gallery.appendChild(hint);
      return;
    }
    var x = axis('x'), y = axis('y'), active = sliders(), chosen = [], wrong = 0, valid = 0;
    for (var i = 0; i < N; i++) {
      if (levelOf(x, i) !== state.cell.x || levelOf(y, i) !== state.cell.y || !matchesSliders(i, active)) continue;
      chosen.push(i);
      if (data.outcome[i] !== INVALID) valid += 1;
      if (data.outcome[i] === 0) wrong += 1;
    }
    var where = [];
    if (x.p >= 0) where.push(x.name + ' = ' + x.labels[state.cell.x]);
    if (y.p >= 0) where.push(y.name + ' = ' + y.labels[state.cell.y]);
    active.forEach(function (p) { where.push(params[p].name + ' = ' + params[p].labels[state.slider[p]]); });
    var heading = document.createElement('h3');
    heading.textContent = where.length ? where.join(' · ') : 'all results';
    var note = document.createElement('p');
    note.className = 'note';
    note.textContent = (valid - wrong) + ' of ' + valid + ' correct (' + S.percent((valid - wrong) / valid) + ')' +
      (chosen.length > data.limit ? ' · showing ' + data.limit + ' of ' + chosen.length + ', wrong ones first' : '');
    var tiles = document.createElement('div');
    tiles.className = 'tiles';
    chosen.slice(0, data.limit).forEach(function (i) {
      var caption = data.pred[i] >= 0 ? data.preds[data.pred[i]] : 'no prediction';
      tiles.appendChild(S.tile(data.thumb[i], OUTCOMES[data.outcome[i]], caption, describe(i, caption)));
    });
    gallery.append(heading, note, tiles);
  }

  function describe(i, caption) {
    var parts = ['job ' + data.job[i]];
    params.forEach(function (param, p) {
      if (data.level[p][i] >= 0) parts.push(param.name + ' = ' + param.labels[data.level[p][i]]);
    });
    return parts.join(' · ') + ' · predicted ' + caption + ' (' + OUTCOMES[data.outcome[i]] + ')';
  }

  function range(n) {
    var out = [];
    for (var i = 0; i < n; i++) out.push(i);
    return out;
  }

  syncControls();
  S.whenDrawn([render()]);
})();
