/* sweep3d report, explorer: each parameter is a heat-map axis, a slider (one value) or pooled.
   The heat map (accuracy and count per cell) is summed here from the counts in #explorer-data:
   the non-empty cells of the joint table over every parameter (mode "joint"), or one table per
   pair of parameters (mode "pairs": no sliders). Clicking a cell shows its sampled images,
   wrong ones first, how many more it holds, and the SQL that lists them all.
   A finding of the findings list (li.finding, its region in data-region as [[parameter, [levels]]])
   filters the explorer to its region when clicked: its parameters become the axes, the counts and
   the images outside it drop out, and the gallery shows its images (a cell click narrows them). */
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
  var sample = data.sample;
  var SAMPLED = sample.job.length;
  var PAIRS = data.mode === 'pairs';
  data.tables.forEach(function (t) {  // where each parameter's column is in each table
    t.pos = params.map(function (_, p) { return t.params.indexOf(p); });
  });
  var OUTCOMES = ['wrong', 'correct', 'invalid', 'not-evaluable'];
  var COUNTED = data.gated ? 'counted' : 'valid';  // counted: valid results of evaluable jobs
  var ROLES = [['x', 'x axis'], ['y', 'y axis'], ['slider', 'slider'], ['pooled', 'pooled']];
  var MAX_CELL_TEXT = 400; // cells beyond which the numbers are left to the hover

  var state = {
    role: params.map(function () { return 'pooled'; }),
    slider: params.map(function () { return 0; }),
    cell: null, // {x: level, y: level} of the clicked cell
    region: null, // {text, terms: [[p, {level: true}]]}: the clicked finding's region
  };
  if (data.defaults.x >= 0) state.role[data.defaults.x] = 'x';
  if (data.defaults.y >= 0) state.role[data.defaults.y] = 'y';

  var plot = document.getElementById('explorer-plot');
  var status = document.getElementById('explorer-status');
  var gallery = document.getElementById('explorer-gallery');
  var widgets = params.map(buildControl);
  var clickBound = false;
  var timings = {};
  S.explorer = {state: state, timings: timings, showRegion: showRegion};

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
      option.disabled = PAIRS && role[0] === 'slider';  // the page carries no counts to slice by
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

  /* The first table holding every parameter in `needed` (-1: none). */
  function tableFor(needed) {
    return data.tables.find(function (t) {
      return needed.every(function (p) { return p < 0 || t.pos[p] >= 0; });
    });
  }

  /* Valid results, correct ones and all results per cell, row-major (y, x): sums of the
     table's cells that match the sliders. */
  function tally(x, y) {
    var size = x.n * y.n, active = sliders(), inRegion = regionTerms();
    var t = tableFor([x.p, y.p].concat(active, inRegion.map(function (r) { return r[0]; })));
    var n = new Float64Array(size), k = new Float64Array(size), total = new Float64Array(size);
    var lx = x.p >= 0 ? t.level[t.pos[x.p]] : null, ly = y.p >= 0 ? t.level[t.pos[y.p]] : null;
    var fixed = active.map(function (p) { return [t.level[t.pos[p]], state.slider[p]]; });
    var within = inRegion.map(function (r) { return [t.level[t.pos[r[0]]], r[1]]; });
    var cells = t.n.length;
    for (var c = 0; c < cells; c++) {
      var match = true;
      for (var s = 0; s < fixed.length && match; s++) match = fixed[s][0][c] === fixed[s][1];
      for (var r = 0; r < within.length && match; r++) match = within[r][1][within[r][0][c]] === true;
      if (!match) continue;
      var cx = lx ? lx[c] : 0, cy = ly ? ly[c] : 0;
      if (cx < 0 || cy < 0) continue;
      var at = cy * x.n + cx;
      n[at] += t.n[c];
      k[at] += t.k[c];
      total[at] += t.total[c];
    }
    return {n: n, k: k, total: total};
  }

  /* Whether sampled result i is at `level` of parameter p (any level when p is -1). */
  function sampledAt(i, p, level) {
    return p < 0 || sample.level[p][i] === level;
  }

  /* The clicked finding's terms, [p, {level: true}] (none without one). */
  function regionTerms() {
    return state.region ? state.region.terms : [];
  }

  function inRegion(i) {
    return regionTerms().every(function (r) { return r[1][sample.level[r[0]][i]] === true; });
  }

  /* Filter the explorer to a finding's region (`terms`: [[parameter name, [levels]]]): its first two
     parameters become the axes, sliders are let go, the gallery shows the region's images. */
  function showRegion(text, named) {
    var terms = [];
    named.forEach(function (term) {
      var p = params.findIndex(function (param) { return param.name === term[0]; });
      if (p < 0) return;
      var levels = {};
      term[1].forEach(function (level) { levels[level] = true; });
      terms.push([p, levels]);
    });
    if (!terms.length) return Promise.resolve();
    state.role = state.role.map(function (role) { return role === 'slider' ? 'pooled' : role; });
    var x = state.role.indexOf('x'), y = state.role.indexOf('y');  // one region parameter: keep the other axis
    setAxes(terms[0][0], terms.length > 1 ? terms[1][0] : (y === terms[0][0] ? x : y));
    state.region = {text: text, terms: terms};
    state.cell = null;
    syncControls();
    showGallery();
    return render();
  }

  function setAxes(px, py) {
    state.role = state.role.map(function (role) { return role === 'x' || role === 'y' ? 'pooled' : role; });
    state.role[px] = 'x';
    if (py >= 0) state.role[py] = 'y';
  }

  function clearRegion() {
    state.region = null;
    state.cell = null;
    document.querySelectorAll('li.finding.active').forEach(function (li) { li.classList.remove('active'); });
    showGallery();
    return render();
  }

  document.querySelectorAll('li.finding:not(.no-region)').forEach(function (li) {
    function choose(event) {
      if (event.target.closest('details')) return;  // its evidence opens, the filter stays
      document.querySelectorAll('li.finding.active').forEach(function (other) { other.classList.remove('active'); });
      li.classList.add('active');
      showRegion(li.dataset.text, JSON.parse(li.dataset.region));
      document.getElementById('explorer').scrollIntoView({block: 'start'});
    }
    li.addEventListener('click', choose);
    li.addEventListener('keydown', function (event) {
      if (event.key === 'Enter' || event.key === ' ') {
        event.preventDefault();
        choose(event);
      }
    });
  });

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
    status.textContent = total + ' ' + COUNTED + ' results ' + (state.region ? 'in the finding\'s region' : 'match the sliders') +
      ' · accuracy ' + S.percent(correct / total) +
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

  /* The clicked cell's sampled images under the current sliders (wrong first, highest loss
     first), its exact counts, and how many of its results the page does not embed. */
  function showGallery() {
    gallery.replaceChildren();
    if (state.region) gallery.append(regionBar());
    if (!state.cell && !state.region) {
      var hint = document.createElement('p');
      hint.className = 'note';
      hint.textContent = 'Click a cell of the heat map to see its images.';
      gallery.appendChild(hint);
      return;
    }
    var x = axis('x'), y = axis('y'), active = sliders(), chosen = [], cell = state.cell;
    var terms = (cell ? [[x.p, cell.x], [y.p, cell.y]] : []).filter(function (t) { return t[0] >= 0; })
      .concat(active.map(function (p) { return [p, state.slider[p]]; }));
    for (var i = 0; i < SAMPLED; i++) {
      if (terms.every(function (t) { return sampledAt(i, t[0], t[1]); }) && inRegion(i)) chosen.push(i);
    }
    var counts = tally(x, y), valid = 0, correct = 0, total = 0;
    for (var at = 0; at < counts.n.length; at++) {
      if (cell && at !== cell.y * x.n + cell.x) continue;
      valid += counts.n[at]; correct += counts.k[at]; total += counts.total[at];
    }
    var heading = document.createElement('h3');
    var named = terms.map(function (t) { return params[t[0]].name + ' = ' + params[t[0]].labels[t[1]]; });
    if (state.region) named.unshift(state.region.text);
    heading.textContent = named.length ? named.join(' · ') : 'all results';
    var shown = Math.min(chosen.length, data.limit);
    var note = document.createElement('p');
    note.className = 'note';
    note.textContent = correct + ' of ' + valid + ' correct (' + S.percent(correct / valid) + ')' +
      (shown < total ? ' · showing ' + shown + ' of ' + total + ', wrong ones first' : '') +
      (total > chosen.length ? ' · ' + (total - chosen.length) + ' more not embedded in this page' : '');
    var tiles = document.createElement('div');
    tiles.className = 'tiles';
    chosen.slice(0, shown).forEach(function (i) {
      var caption = sample.pred[i] >= 0 ? data.preds[sample.pred[i]] : 'no prediction';
      if (sample.why && sample.why[i] >= 0) caption += ' · ' + data.whys[sample.why[i]];
      tiles.appendChild(S.tile(sample.thumb[i], OUTCOMES[sample.outcome[i]], caption, describe(i, caption)));
    });
    gallery.append(heading, note, tiles);
    if (shown < total) gallery.append(listing(terms));
  }

  /* The finding the explorer is filtered to, and a button letting it go. */
  function regionBar() {
    var bar = document.createElement('p');
    bar.className = 'note region-bar';
    var button = document.createElement('button');
    button.type = 'button';
    button.textContent = 'show all results';
    button.addEventListener('click', clearRegion);
    bar.append('Filtered to the finding ', Object.assign(document.createElement('b'), {textContent: state.region.text}),
               ' (its levels on the explorer\'s axes; a bin is in when its middle is) ', button);
    return bar;
  }

  /* "List them all": the `sweep3d query` printing every result of the cell, in gallery order. */
  function listing(terms) {
    function inLevels(p, levels) {
      return 'job IN (SELECT job FROM control_levels WHERE parameter = \'' +
        params[p].name.replace(/'/g, "''") + '\' AND level ' + levels + ')';
    }
    var where = terms.map(function (t) { return inLevels(t[0], '= ' + t[1]); }).concat(
      regionTerms().map(function (r) { return inLevels(r[0], 'IN (' + Object.keys(r[1]).join(', ') + ')'); }));
    var box = document.createElement('p');
    box.className = 'note listing';
    var code = document.createElement('code');
    code.textContent = 'sweep3d query ' + data.query.spec + ' "SELECT * FROM results' +
      (where.length ? ' WHERE ' + where.join(' AND ') : '') + ' ' + data.query.order + '"';
    box.append('Every result of this cell: ', code);
    return box;
  }

  function describe(i, caption) {
    var parts = ['job ' + sample.job[i]];
    params.forEach(function (param, p) {
      if (sample.level[p][i] >= 0) parts.push(param.name + ' = ' + param.labels[sample.level[p][i]]);
    });
    return parts.join(' · ') + ' · predicted ' + caption + ' (' + OUTCOMES[sample.outcome[i]] + ')';
  }

  function range(n) {
    var out = [];
    for (var i = 0; i < n; i++) out.push(i);
    return out;
  }

  syncControls();
  S.whenDrawn([render()]);
})();
