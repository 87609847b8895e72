// The alignment page (sweep3d.followups.realism.align): the live camera with a shot's render or edges laid over it.
// Data comes from the JSON block #shots and is only ever printed as text (textContent), never parsed as markup.
(() => {
  'use strict';
  const shots = JSON.parse(document.getElementById('shots').textContent);
  const $ = (id) => document.getElementById(id);
  const root = document.documentElement;
  const stage = $('stage'), video = $('video'), photo = $('photo'), overlay = $('overlay');
  const notice = $('notice'), statusLine = $('status');
  const prev = $('prev'), next = $('next'), toggle = $('toggle'), opacity = $('opacity'), opacityValue = $('opacity-value');
  const capture = $('capture'), take = $('take'), file = $('file'), save = $('save');
  const JPEG_QUALITY = 0.92;
  const state = { index: 0, edges: false, mode: null, photoFile: null, photoUrl: null, saved: new Set(), wakeLock: null };

  // The centred rectangle of aspect w:h that fits inside a boxW × boxH box (object-fit: contain).
  function fit(boxW, boxH, w, h) {
    const s = Math.min(boxW / w, boxH / h);
    return { x: (boxW - w * s) / 2, y: (boxH - h * s) / 2, w: w * s, h: h * s };
  }

  // The overlay: the render's aspect, fitted and centred inside the frame as displayed (the camera's or the photo's).
  function layout() {
    const shot = shots[state.index];
    const sw = stage.clientWidth, sh = stage.clientHeight;
    let fw = 0, fh = 0;
    if (state.mode === 'live') { fw = video.videoWidth; fh = video.videoHeight; }
    else if (state.photoUrl && photo.complete) { fw = photo.naturalWidth; fh = photo.naturalHeight; }
    const frame = fw && fh ? fit(sw, sh, fw, fh) : { x: 0, y: 0, w: sw, h: sh };
    const box = fit(frame.w, frame.h, shot.width, shot.height);
    overlay.style.left = `${frame.x + box.x}px`;
    overlay.style.top = `${frame.y + box.y}px`;
    overlay.style.width = `${box.w}px`;
    overlay.style.height = `${box.h}px`;
  }

  function setStatus(text) { statusLine.textContent = text; }

  function fileName(shot) { return `${shot.job_id}.jpg`; }

  function showShot(index) {
    state.index = Math.max(0, Math.min(shots.length - 1, index));
    const shot = shots[state.index];
    $('counter').textContent = `${state.index + 1} / ${shots.length}${state.saved.has(state.index) ? ' \u2713' : ''}`;
    $('job').textContent = shot.job_id;
    $('caption').textContent = shot.caption;
    prev.disabled = state.index === 0;
    next.disabled = state.index === shots.length - 1;
    overlay.src = state.edges ? shot.edges : shot.render;
    overlay.hidden = false;
    root.dataset.shot = String(state.index);
    clearPhoto();  // a photo belongs to the shot it was taken for
    setStatus('');
    layout();
  }

  function setOpacity() {
    overlay.style.opacity = String(opacity.value / 100);
    opacityValue.textContent = `${opacity.value}%`;
  }

  function setEdges(edges) {
    state.edges = edges;
    toggle.setAttribute('aria-pressed', String(edges));
    overlay.src = edges ? shots[state.index].edges : shots[state.index].render;
  }

  function download(blob, name) {
    const url = URL.createObjectURL(blob);
    const link = document.createElement('a');
    link.href = url;
    link.download = name;
    link.hidden = true;
    document.body.appendChild(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60000);
  }

  function saved(name, w, h) {
    state.saved.add(state.index);
    $('counter').textContent = `${state.index + 1} / ${shots.length} \u2713`;
    setStatus(`Saved ${name} (${w}\u00d7${h})`);
  }

  function encodeJpeg(source, w, h) {
    const canvas = document.createElement('canvas');
    canvas.width = w;
    canvas.height = h;
    canvas.getContext('2d').drawImage(source, 0, 0, w, h);
    return new Promise((resolve, reject) => canvas.toBlob(
      (blob) => (blob ? resolve(blob) : reject(new Error('the browser could not encode a JPEG'))), 'image/jpeg', JPEG_QUALITY));
  }

  // Live mode: the camera frame at the stream's full resolution, without the overlay.
  async function captureFrame() {
    const w = video.videoWidth, h = video.videoHeight;
    if (!w || !h) { setStatus('The camera has not delivered a frame yet; try again in a moment.'); return; }
    const shot = shots[state.index];
    try {
      download(await encodeJpeg(video, w, h), fileName(shot));
      saved(fileName(shot), w, h);
    } catch (err) {
      setStatus(`Not saved: ${err.message}`);
    }
  }

  // Fallback mode: a JPEG from the phone's camera is saved as it is (its EXIF orientation kept);
  // another format is drawn upright and encoded as JPEG.
  async function savePhoto() {
    if (!state.photoFile) return;
    const shot = shots[state.index], w = photo.naturalWidth, h = photo.naturalHeight;
    try {
      download(state.photoFile.type === 'image/jpeg' ? state.photoFile : await encodeJpeg(photo, w, h), fileName(shot));
      saved(fileName(shot), w, h);
    } catch (err) {
      setStatus(`Not saved: ${err.message}`);
    }
  }

  function clearPhoto() {
    if (state.photoUrl) URL.revokeObjectURL(state.photoUrl);
    state.photoFile = null;
    state.photoUrl = null;
    photo.hidden = true;
    photo.removeAttribute('src');
    save.disabled = true;
    delete root.dataset.photo;
  }

  function setPhoto(chosen) {
    clearPhoto();
    state.photoFile = chosen;
    state.photoUrl = URL.createObjectURL(chosen);
    photo.onload = () => {
      photo.hidden = false;
      save.disabled = false;
      root.dataset.photo = '1';
      layout();
      setStatus(`Photo ${photo.naturalWidth}\u00d7${photo.naturalHeight}: compare it with the overlay, then save it or take it again.`);
    };
    photo.onerror = () => { clearPhoto(); setStatus('That file is not an image this browser can show.'); };
    photo.src = state.photoUrl;
  }

  function fallback(why) {
    state.mode = 'photo';
    root.dataset.mode = 'photo';
    notice.textContent = `No live camera: ${why}. Take the photo with the phone's camera; it shows under the overlay to check before you save it.`;
    notice.hidden = false;
    take.hidden = false;
    save.hidden = false;
    layout();
  }

  function liveCameraProblem() {
    if (!window.isSecureContext) return 'browsers allow it only on a secure page (a local file, localhost or https)';
    if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) return 'this browser gives web pages no camera';
    return null;
  }

  function cameraError(err) {
    switch (err && err.name) {
      case 'NotAllowedError': case 'SecurityError': return 'the camera permission was denied';
      case 'NotFoundError': case 'OverconstrainedError': return 'no camera was found';
      case 'NotReadableError': case 'AbortError': return 'the camera is in use or could not start';
      default: return `the camera could not start (${err && err.name ? err.name : err})`;
    }
  }

  async function keepAwake() {
    try {
      if (navigator.wakeLock && document.visibilityState === 'visible') state.wakeLock = await navigator.wakeLock.request('screen');
    } catch (err) { /* a screen that dims is no failure */ }
  }

  async function start() {
    const problem = liveCameraProblem();
    if (problem) { fallback(problem); return; }
    let stream;
    try {
      stream = await navigator.mediaDevices.getUserMedia({
        audio: false,
        // the rear camera where there is one, at its largest native size (uncropped, unscaled)
        video: { facingMode: { ideal: 'environment' }, width: { ideal: 4096 }, height: { ideal: 4096 }, resizeMode: 'none' },
      });
    } catch (err) {
      fallback(cameraError(err));
      return;
    }
    state.mode = 'live';
    root.dataset.mode = 'live';
    video.srcObject = stream;
    video.hidden = false;
    capture.hidden = false;
    video.addEventListener('loadedmetadata', layout);
    video.addEventListener('resize', layout);  // the stream's size changes when a phone turns
    try { await video.play(); } catch (err) { setStatus('Tap the camera view to start it.'); }
    stage.addEventListener('click', () => { if (video.paused) video.play().catch(() => {}); });
    keepAwake();
    document.addEventListener('visibilitychange', keepAwake);
    layout();
  }

  prev.addEventListener('click', () => showShot(state.index - 1));
  next.addEventListener('click', () => showShot(state.index + 1));
  toggle.addEventListener('click', () => setEdges(!state.edges));
  opacity.addEventListener('input', setOpacity);
  capture.addEventListener('click', captureFrame);
  save.addEventListener('click', savePhoto);
  file.addEventListener('change', () => {
    const chosen = file.files && file.files[0];
    if (chosen) setPhoto(chosen);
    file.value = '';  // choosing the same photo again is a change too
  });
  document.addEventListener('keydown', (event) => {
    if (event.target instanceof HTMLInputElement) return;  // the slider's own arrows
    if (event.key === 'ArrowLeft') showShot(state.index - 1);
    if (event.key === 'ArrowRight') showShot(state.index + 1);
  });
  window.addEventListener('resize', layout);
  if (window.ResizeObserver) new ResizeObserver(layout).observe(stage);

  setOpacity();
  showShot(0);
  start().finally(() => { root.dataset.ready = '1'; });
})();
