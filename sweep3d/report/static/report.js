/* sweep3d report: draws the figures, fills in the thumbnails, and shares helpers with the
   explorer (window.sweep3d). Data comes only from the page's JSON blocks; text from a spec or
   a model reaches the page through textContent, or escaped for plotly (plotText).

   Figures on screen are drawn first; the others as they near the viewport, or one by one
   once the page is ready. Panels past the first screen are folded (<details class="panel">);
   their plots are fitted to the width when they open. <html data-ready="1"> marks the page interactive (the explorer
   and the figures on screen drawn), data-drawn="1" every figure drawn. */
(function () {
  'use strict';

  var PLOT_CONFIG = {
    displaylogo: false,
    responsive: true,
    modeBarButtonsToRemove: ['select2d', 'lasso2d', 'sendChartToCloud'],  // nothing leaves the page
  };
  var thumbs = JSON.parse(document.getElementById('thumbs').textContent);
  var thumbProblems = JSON.parse(document.getElementById('thumb-problems').textContent);  // index -> why none
  var figures = Array.prototype.map.call(document.querySelectorAll('script.fig-data'), function (node) {
    return {source: node, target: document.getElementById(node.dataset.target), drawn: null};
  });

  /* Text for plotly labels, which read a small HTML subset: escaped so names show literally. */
  function plotText(value) {
    return String(value).replace(/&/g, '&amp;').replace(/</g, '&lt;').replace(/>/g, '&gt;');
  }

  /* Draw a figure into the element `node`; PNG export in the mode bar. Returns a promise. */
  function draw(node, figure) {
    var config = Object.assign({}, PLOT_CONFIG, {
      toImageButtonOptions: {format: 'png', scale: 2, filename: node.id || 'sweep3d-figure'},
    });
    return Plotly.react(node, figure.data, figure.layout, config);
  }

  function drawFigure(figure) {
    if (!figure.drawn) figure.drawn = draw(figure.target, JSON.parse(figure.source.textContent));
    return figure.drawn;
  }

  /* Give an <img data-thumb="i"> its image, or swap it for a placeholder saying why there is none. */
  function fillThumb(img) {
    var uri = thumbs[Number(img.dataset.thumb)];
    if (uri) {
      img.src = uri;
      return;
    }
    var problem = thumbProblems[img.dataset.thumb];
    var missing = document.createElement('div');
    missing.className = 'missing';
    missing.textContent = problem || 'no image';
    missing.title = problem ? img.alt + ': image ' + problem : img.alt;
    img.replaceWith(missing);
  }

  /* A gallery tile: thumbnail with a border for the outcome, and a caption. */
  function tile(index, outcome, caption, title) {
    var figure = document.createElement('figure');
    figure.className = 'tile ' + outcome;
    figure.title = title;
    var img = document.createElement('img');
    img.dataset.thumb = String(index);
    img.alt = caption;
    figure.appendChild(img);
    var text = document.createElement('figcaption');
    text.textContent = caption;
    figure.appendChild(text);
    fillThumb(img);
    return figure;
  }

  /* Wilson 95 % score interval of k successes in n trials, as [low, high]: the views' wilson_low
     and wilson_high (sweep3d/stages/aggregate/views.py), clamped alike to [0, p] and [p, 1]. */
  function wilson(k, n) {
    if (!n) return [NaN, NaN];
    var z = 1.959963984540054, p = k / n, z2 = z * z;
    var centre = (p + z2 / (2 * n)) / (1 + z2 / n);
    var half = z * Math.sqrt(Math.max(p * (1 - p) / n + z2 / (4 * n * n), 0)) / (1 + z2 / n);
    return [Math.min(p, Math.max(0, centre - half)), Math.max(p, Math.min(1, centre + half))];
  }

  function percent(value, digits) {
    return isFinite(value) ? (100 * value).toFixed(digits === undefined ? 1 : digits) + '%' : '–';
  }

  /* Resolves once the figures on screen are drawn; draws the others as they come near. */
  function drawVisible() {
    return new Promise(function (resolve) {
      var first = true;
      var observer = new IntersectionObserver(function (entries) {
        var now = [];
        entries.forEach(function (entry) {
          if (!entry.isIntersecting) return;
          var figure = figures.find(function (f) { return f.target === entry.target; });
          observer.unobserve(entry.target);
          now.push(drawFigure(figure));
        });
        if (first) {
          first = false;
          resolve(Promise.all(now));
        }
      }, {rootMargin: '200px'});
      figures.forEach(function (f) { observer.observe(f.target); });
      if (!figures.length) resolve(Promise.resolve());
    });
  }

  /* Draw the figures still undrawn, one per task so the page stays responsive. */
  function drawRest() {
    return new Promise(function (resolve) {
      var queue = figures.slice();
      (function next() {
        while (queue.length && queue[0].drawn) queue.shift();
        if (!queue.length) {
          Promise.all(figures.map(drawFigure)).then(resolve);
          return;
        }
        drawFigure(queue.shift()).then(function () { setTimeout(next, 0); });
      })();
    });
  }

  /* Folded panels: a plot drawn while folded has no width to fit; it is fitted when its panel opens.
     A link to a folded panel (the navigation, "#not-evaluable") opens it. */
  function fitPlots(root) {
    root.querySelectorAll('.js-plotly-plot').forEach(function (plot) { Plotly.Plots.resize(plot); });
  }
  function unfold(id) {
    var target = id && document.getElementById(id);
    var panel = target && target.closest('section.folded');
    var details = panel && panel.querySelector('details.panel');
    if (details && !details.open) details.open = true;
  }
  document.querySelectorAll('details.panel').forEach(function (details) {
    details.addEventListener('toggle', function () { if (details.open) fitPlots(details); });
  });
  document.addEventListener('click', function (event) {
    var link = event.target.closest && event.target.closest('a[href^="#"]');
    if (link) unfold(decodeURIComponent(link.getAttribute('href').slice(1)));
  });
  window.addEventListener('hashchange', function () { unfold(decodeURIComponent(location.hash.slice(1))); });
  if (location.hash) unfold(decodeURIComponent(location.hash.slice(1)));

  document.querySelectorAll('img[data-thumb]').forEach(fillThumb);
  var visible = drawVisible();

  window.sweep3d = {
    plotText: plotText, draw: draw, tile: tile, wilson: wilson, percent: percent,
    /* Open every folded panel and fit its plots (what a reader clicking each title sees). */
    unfoldAll: function () {
      document.querySelectorAll('details.panel').forEach(function (d) { d.open = true; });
      return Promise.all(Array.prototype.map.call(document.querySelectorAll('.js-plotly-plot'),
                                                  function (plot) { return Plotly.Plots.resize(plot); }));
    },
    /* Mark the page ready once `promises` and the figures on screen are drawn, then draw the rest. */
    whenDrawn: function (promises) {
      Promise.all([visible].concat(promises)).then(function () {
        window.sweep3d.readyAt = performance.now();
        document.documentElement.dataset.ready = '1';
        return drawRest();
      }).then(function () {
        window.sweep3d.drawnAt = performance.now();
        document.documentElement.dataset.drawn = '1';
      });
    },
  };
})();
