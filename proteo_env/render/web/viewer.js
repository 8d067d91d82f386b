/* proteo episode viewer: plays the episode in the #proteo-data JSON script element with three.js (global THREE).
 *
 * The page exposes its state for scripts and tests: <body data-ready data-frame data-cycle data-frames
 * data-modules data-drawn (modules drawn) data-draws (pictures drawn) data-errors data-error data-picked
 * data-load-ms>, document.title with the
 * cycle and module count, and window.proteoViewer (seek, step, play, pause, render, project, pick, state).
 * A URL fragment #frame=F (negative: from the end) or #cycle=C opens the episode there.
 */
(function () {
  'use strict';
  const body = document.body;
  const $ = (id) => document.getElementById(id);
  const errors = [];

  function reportError(message) {
    errors.push(String(message));
    body.dataset.errors = String(errors.length);
    body.dataset.error = errors[0];
    const box = $('error');
    box.hidden = false;
    box.textContent = 'Error: ' + errors.join('\n');
    document.title = 'proteo · error: ' + errors[0];
  }
  window.addEventListener('error', (e) => reportError(e.message || e.error));
  window.addEventListener('unhandledrejection', (e) => reportError((e.reason && e.reason.message) || e.reason));

  // ------------------------------------------------------------------ data
  const TYPED = { int8: Int8Array, int16: Int16Array, int32: Int32Array };

  function base64Bytes(text) {
    const binary = atob(text);
    const bytes = new Uint8Array(binary.length);
    for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
    return bytes;
  }

  /** The typed array of a packed array (still differenced along time when packed.delta). */
  async function unpack(packed) {
    const stream = new Blob([base64Bytes(packed.zlib_base64)]).stream().pipeThrough(new DecompressionStream('deflate'));
    const buffer = await new Response(stream).arrayBuffer();
    const values = new TYPED[packed.dtype](buffer);
    const expected = packed.shape.reduce((a, b) => a * b, 1);
    if (values.length !== expected) throw new Error(`packed array of ${values.length} values, expected ${expected}`);
    return values;
  }

  function hexColour(hex) {
    const h = hex.replace('#', '');
    return [0, 2, 4].map((i) => parseInt(h.slice(i, i + 2), 16) / 255);
  }

  /** Per-module state at one frame, moved between frames by adding or subtracting the stored differences. */
  class Episode {
    constructor(meta, dPositions, dModes, dScents) {
      this.T = meta.n_frames; this.N = meta.n_modules; this.C = meta.n_channels;
      this.dPositions = dPositions; this.dModes = dModes; this.dScents = dScents;
      this.positions = new Int32Array(this.N * 3);
      this.modes = new Int32Array(this.N);
      this.scents = new Int32Array(this.C * this.N);
      this.reset();
    }

    reset() {
      this.positions.set(this.dPositions.subarray(0, this.positions.length));
      this.modes.set(this.dModes.subarray(0, this.modes.length));
      this.scents.set(this.dScents.subarray(0, this.scents.length));
      this.frame = 0;
    }

    static add(state, deltas, offset, sign) {
      if (sign > 0) for (let i = 0; i < state.length; i++) state[i] += deltas[offset + i];
      else for (let i = 0; i < state.length; i++) state[i] -= deltas[offset + i];
    }

    /** Apply frame t's differences forwards (sign +1: t-1 -> t) or backwards (sign -1: t -> t-1). */
    apply(t, sign) {
      Episode.add(this.positions, this.dPositions, t * this.positions.length, sign);
      Episode.add(this.modes, this.dModes, t * this.modes.length, sign);
      Episode.add(this.scents, this.dScents, t * this.scents.length, sign);
    }

    seek(target) {
      target = Math.max(0, Math.min(this.T - 1, target | 0));
      if (Math.abs(target - this.frame) > target) this.reset();
      while (this.frame < target) this.apply(++this.frame, +1);
      while (this.frame > target) this.apply(this.frame--, -1);
    }
  }

  // ------------------------------------------------------------------ scene
  function cellGeometry(faceQuads) {
    const positions = [], normals = [];
    for (const quad of faceQuads) {
      const [a, b, c, d] = quad.map((p) => new THREE.Vector3(...p));
      const centre = new THREE.Vector3().add(a).add(b).add(c).add(d).multiplyScalar(0.25);
      const normal = new THREE.Vector3().subVectors(b, a).cross(new THREE.Vector3().subVectors(c, a)).normalize();
      const corners = normal.dot(centre) > 0 ? [a, b, c, a, c, d] : [a, c, b, a, d, c];
      if (normal.dot(centre) < 0) normal.negate();
      for (const p of corners) { positions.push(p.x, p.y, p.z); normals.push(normal.x, normal.y, normal.z); }
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
    geometry.setAttribute('normal', new THREE.Float32BufferAttribute(normals, 3));
    return geometry;
  }

  /** Corners (4 x 3 per face, wound to face outwards) and unit normals of the 12 faces of a cell at the origin. */
  function faceCorners(faceQuads) {
    return faceQuads.map((quad) => {
      const [a, b, c] = quad.map((p) => new THREE.Vector3(...p));
      const centre = quad.reduce((sum, p) => sum.add(new THREE.Vector3(...p)), new THREE.Vector3()).multiplyScalar(0.25);
      const outward = new THREE.Vector3().subVectors(b, a).cross(new THREE.Vector3().subVectors(c, a)).dot(centre) > 0;
      const order = outward ? quad : [quad[0], quad[3], quad[2], quad[1]];
      return { corners: order.flat(), normal: centre.clone().normalize().toArray() };
    });
  }

  function staticCells(geometry, sites, colour, clipping) {
    const count = sites.length / 3;
    const mesh = new THREE.InstancedMesh(geometry, new THREE.MeshLambertMaterial({ color: new THREE.Color(...hexColour(colour)), clippingPlanes: clipping }), Math.max(count, 1));
    mesh.count = count;
    const m = mesh.instanceMatrix.array;
    for (let i = 0; i < count; i++) {
      m.fill(0, 16 * i, 16 * i + 16);
      m[16 * i] = m[16 * i + 5] = m[16 * i + 10] = m[16 * i + 15] = 1;
      m[16 * i + 12] = sites[3 * i]; m[16 * i + 13] = sites[3 * i + 1]; m[16 * i + 14] = sites[3 * i + 2];
    }
    mesh.instanceMatrix.needsUpdate = true;
    mesh.computeBoundingSphere();
    return mesh;
  }

  function floorMeshes(meta) {
    const xMax = (meta.box[0] || 1) - 1, yMax = (meta.box[1] || 1) - 1, z = meta.floor_level;
    const lo = [-1.5, -1.5], hi = [xMax + 1.5, yMax + 1.5];
    const plane = new THREE.Mesh(new THREE.PlaneGeometry(hi[0] - lo[0], hi[1] - lo[1]),
      new THREE.MeshBasicMaterial({ color: new THREE.Color(...hexColour(meta.colours.floor)) }));
    plane.position.set((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, z);
    const step = Math.max(2, 2 * Math.ceil(Math.max(xMax, yMax) / 100));
    const lines = [];
    for (let x = 0; x <= xMax; x += step) lines.push(x, lo[1], z + 0.01, x, hi[1], z + 0.01);
    for (let y = 0; y <= yMax; y += step) lines.push(lo[0], y, z + 0.01, hi[0], y, z + 0.01);
    const grid = new THREE.BufferGeometry();
    grid.setAttribute('position', new THREE.Float32BufferAttribute(lines, 3));
    return [plane, new THREE.LineSegments(grid, new THREE.LineBasicMaterial({ color: new THREE.Color(...hexColour('#b3ad9f')) }))];
  }

  // ------------------------------------------------------------------ viewer
  async function start() {
    const meta = JSON.parse($('proteo-data').textContent);
    if (meta.format !== 'proteo-view') throw new Error(`episode data of format ${meta.format}, expected proteo-view`);
    const [dPositions, dModes, dScents, anchored, solidSites, objectSites] = await Promise.all(
      ['positions', 'modes', 'scents', 'anchored', 'solid_sites', 'object_sites'].map((k) => unpack(meta[k])));
    const episode = new Episode(meta, dPositions, dModes, dScents);
    const N = meta.n_modules, T = meta.n_frames;
    const names = meta.mode_names;
    const palette = meta.mode_colours.map(hexColour);
    const searchDeep = meta.search_mode >= 0 ? palette[meta.search_mode] : [0, 0, 0];
    const searchFar = hexColour(meta.search_far);
    const shown = names.map(() => true);

    $('heading').textContent = `${meta.task_id} · ${meta.policy} · seed ${meta.seed}`;
    $('readout').textContent = `${N.toLocaleString('en')} modules · ${meta.cycles[T - 1]} cycles · ` +
      (meta.success ? 'success' : 'no success') + ` · proteo ${meta.package_version}`;
    body.dataset.frames = String(T);
    body.dataset.modules = String(N);

    // renderer, camera, light as in the pictures: colour x (ambient + (1 - ambient) x Lambert), no colour conversion
    THREE.ColorManagement.enabled = false;
    const canvas = $('view');
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: N <= 5000 });
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.localClippingEnabled = true;
    renderer.setClearColor(new THREE.Color(...hexColour(meta.colours.background)));
    const scene = new THREE.Scene();
    const camera = new THREE.PerspectiveCamera(35, 1, 0.1, 5000);
    camera.up.set(0, 0, 1);
    scene.add(camera);
    scene.add(new THREE.AmbientLight(0xffffff, meta.light.ambient * Math.PI));
    const sun = new THREE.DirectionalLight(0xffffff, (1 - meta.light.ambient) * Math.PI);
    sun.position.set(...meta.light.direction_in_camera).normalize();
    camera.add(sun);
    camera.add(sun.target);

    const cut = new THREE.Plane(new THREE.Vector3(-1, 0, 0), 0);
    const clipping = [];
    const geometry = cellGeometry(meta.face_quads);
    // modules are drawn face by face, in one mesh rebuilt per picture: only the faces that look onto a
    // free site and towards the camera (a software WebGL draws one big mesh far faster than instances).
    // Colours travel as normalised bytes, RGBA: a third of the float triples' bytes copied to the GPU per
    // picture (3-byte colours with 16-bit corners were much slower in SwiftShader).
    const directions = meta.directions, faces = faceCorners(meta.face_quads);
    const maxFaces = Math.max(N * 12, 1);
    const faceGeometry = new THREE.BufferGeometry();
    for (const [name, array, size, normalized] of [['position', new Float32Array(maxFaces * 12), 3, false], ['color', new Uint8Array(maxFaces * 16), 4, true]]) {
      const attribute = new THREE.BufferAttribute(array, size, normalized);
      attribute.setUsage(THREE.DynamicDrawUsage);
      faceGeometry.setAttribute(name, attribute);
    }
    const index = new Uint32Array(maxFaces * 6);
    for (let f = 0; f < maxFaces; f++) index.set([4 * f, 4 * f + 1, 4 * f + 2, 4 * f, 4 * f + 2, 4 * f + 3], 6 * f);
    faceGeometry.setIndex(new THREE.BufferAttribute(index, 1));
    // faces are flat and the light turns with the camera, so each face's shade is computed here, once per
    // face and picture, as in the pictures: colour x (ambient + (1 - ambient) x max(0, normal . light)), in bytes
    const modules = new THREE.Mesh(faceGeometry, new THREE.MeshBasicMaterial({ vertexColors: true, clippingPlanes: clipping }));
    const faceShade = new Float32Array(12), lightWorld = new THREE.Vector3();
    modules.frustumCulled = false;
    scene.add(modules);
    const faceModule = new Int32Array(maxFaces);  // face -> module id
    let drawnCount = 0, faceCount = 0;
    scene.add(staticCells(geometry, solidSites, meta.colours.solid, clipping));
    scene.add(staticCells(geometry, objectSites, meta.colours.object, clipping));
    if (meta.floor) for (const mesh of floorMeshes(meta)) scene.add(mesh);
    const marker = new THREE.Mesh(geometry, new THREE.MeshBasicMaterial({ color: 0x000000, wireframe: true }));
    marker.scale.setScalar(1.06);
    marker.visible = false;
    scene.add(marker);
    let picked = -1;

    // framing: the box of every site visited (every frame's modules, obstacles, object)
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    const grow = (sites, n) => { for (let i = 0; i < n; i++) for (let k = 0; k < 3; k++) { const v = sites[3 * i + k]; if (v < lo[k]) lo[k] = v; if (v > hi[k]) hi[k] = v; } };
    for (let t = 0; t < T; t += Math.max(1, Math.floor(T / 64))) { episode.seek(t); grow(episode.positions, N); }
    episode.seek(T - 1); grow(episode.positions, N);
    grow(solidSites, solidSites.length / 3); grow(objectSites, objectSites.length / 3);
    if (!isFinite(lo[0])) { lo.fill(0); hi.fill(0); }
    // occupancy of the sites around everything visited (outside it every site counts as free)
    const gridLo = lo.map((v) => v - 2), gridSize = [0, 1, 2].map((k) => hi[k] - lo[k] + 5);
    const gridVolume = gridSize[0] * gridSize[1] * gridSize[2];
    const useGrid = gridVolume <= 64e6;
    const grid = new Uint8Array(useGrid ? gridVolume : 1), staticGrid = new Uint8Array(grid.length);
    const cellIndex = (x, y, z) => {
      x -= gridLo[0]; y -= gridLo[1]; z -= gridLo[2];
      if (x < 0 || y < 0 || z < 0 || x >= gridSize[0] || y >= gridSize[1] || z >= gridSize[2]) return -1;
      return (x * gridSize[1] + y) * gridSize[2] + z;
    };
    if (useGrid) {
      for (const sites of [solidSites, objectSites]) for (let i = 0; i < sites.length; i += 3) {
        const at = cellIndex(sites[i], sites[i + 1], sites[i + 2]);
        if (at >= 0) staticGrid[at] = 1;
      }
      if (meta.floor) for (let x = 0; x < gridSize[0]; x++) for (let y = 0; y < gridSize[1]; y++) for (let z = 0; z < gridSize[2] && z + gridLo[2] < 0; z++) staticGrid[(x * gridSize[1] + y) * gridSize[2] + z] = 1;
    }
    const centre = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
    const radius = Math.max(3, 0.5 * Math.hypot(hi[0] - lo[0] + 2, hi[1] - lo[1] + 2, hi[2] - lo[2] + 2));
    const controls = new THREE.OrbitControls(camera, canvas);
    controls.target.copy(centre);
    controls.enableDamping = false;
    function frameView() {
      const distance = 0.62 * radius / Math.sin(Math.PI / 180 * camera.fov / 2) / Math.min(1, camera.aspect);
      camera.position.copy(centre).addScaledVector(new THREE.Vector3(...meta.view_direction), distance);
      controls.target.copy(centre);
      controls.update();
    }

    // ---------------------------------------------------------------- drawing
    let dirty = true, facesStale = true, orderStale = true;
    const requestDraw = () => { dirty = true; };
    controls.addEventListener('change', () => { facesStale = orderStale = true; requestDraw(); });
    // modules nearest the camera first, so that the depth test spares the pixels of the faces they hide
    // (sorted when the camera moves; modules stepping meanwhile only make the order a little less good)
    const order = new Uint32Array(N).map((_, i) => i), depth = new Float32Array(N);
    function sortByDepth() {
      const p = episode.positions, e = camera.position;
      for (let i = 0; i < N; i++) depth[i] = (p[3 * i] - e.x) ** 2 + (p[3 * i + 1] - e.y) ** 2 + (p[3 * i + 2] - e.z) ** 2;
      order.sort((a, b) => depth[a] - depth[b]);
      orderStale = false;
    }

    const cutSide = new Float32Array(Math.max(N, 1));  // signed distance of each module's centre to the cut plane
    function moduleColour(i, md, out, o) {
      if (md === meta.search_mode && meta.n_channels > 0) {
        const s = episode.scents[i];
        const t = s < 0 ? 1 : Math.min(s / Math.max(meta.scent_scale, 1), 1);
        for (let k = 0; k < 3; k++) out[o + k] = (1 - t) * searchDeep[k] + t * searchFar[k];
      } else {
        const rgb = palette[md];
        out[o] = rgb[0]; out[o + 1] = rgb[1]; out[o + 2] = rgb[2];
      }
    }

    /** Fill the face instances of the current frame: shown modules' faces onto free sites, turned to the camera. */
    function updateModules() {
      const vp = faceGeometry.attributes.position.array, vc = faceGeometry.attributes.color.array;
      camera.updateMatrixWorld();
      lightWorld.set(...meta.light.direction_in_camera).normalize().transformDirection(camera.matrixWorld);
      for (let d = 0; d < 12; d++) {
        const n = faces[d].normal;
        faceShade[d] = 255 * (meta.light.ambient + (1 - meta.light.ambient) * Math.max(0, n[0] * lightWorld.x + n[1] * lightWorld.y + n[2] * lightWorld.z));
      }
      const pos = episode.positions, mode = episode.modes;
      const cutting = clipping.length > 0;
      if (useGrid) grid.set(staticGrid);
      for (let i = 0; i < N; i++) {
        const x = pos[3 * i], y = pos[3 * i + 1], z = pos[3 * i + 2];
        cutSide[i] = cutting ? cut.normal.x * x + cut.normal.y * y + cut.normal.z * z + cut.constant : 2;
        if (!useGrid || !shown[mode[i]] || cutSide[i] < 1) continue;  // a cell the plane cuts hides nothing
        const at = cellIndex(x, y, z);
        if (at >= 0) grid[at] = 1;
      }
      if (orderStale) sortByDepth();
      const eye = camera.position;
      const colour = [0, 0, 0];
      let f = 0, k = 0;
      for (let j = 0; j < N; j++) {
        const i = order[j], md = mode[i];
        if (!shown[md] || cutSide[i] <= -1) continue;
        const x = pos[3 * i], y = pos[3 * i + 1], z = pos[3 * i + 2];
        const ex = eye.x - x, ey = eye.y - y, ez = eye.z - z;
        moduleColour(i, md, colour, 0);
        k++;
        for (let d = 0; d < 12; d++) {
          const dir = directions[d];
          if (dir[0] * ex + dir[1] * ey + dir[2] * ez <= 1) continue;  // turned away from the camera
          if (useGrid) {
            const at = cellIndex(x + dir[0], y + dir[1], z + dir[2]);
            if (at >= 0 && grid[at]) continue;  // hidden by a neighbour
          }
          const corners = faces[d].corners, shade = faceShade[d];
          const r = colour[0] * shade + 0.5, g = colour[1] * shade + 0.5, b = colour[2] * shade + 0.5;  // rounded, as bytes truncate
          for (let v = 0, o = 12 * f, c = 16 * f; v < 12; v += 3, o += 3, c += 4) {
            vp[o] = x + corners[v]; vp[o + 1] = y + corners[v + 1]; vp[o + 2] = z + corners[v + 2];
            vc[c] = r; vc[c + 1] = g; vc[c + 2] = b; vc[c + 3] = 255;
          }
          faceModule[f++] = i;
        }
      }
      faceGeometry.setDrawRange(0, 6 * f);
      for (const name of ['position', 'color']) {
        const attribute = faceGeometry.attributes[name];
        attribute.clearUpdateRanges();
        attribute.addUpdateRange(0, 4 * attribute.itemSize * f);
        attribute.needsUpdate = true;
      }
      faceGeometry.boundingSphere = null;  // recomputed when a click needs it
      faceCount = f;
      if (picked >= 0) {
        marker.position.set(pos[3 * picked], pos[3 * picked + 1], pos[3 * picked + 2]);
        marker.visible = shown[mode[picked]];
      }
      drawnCount = k;
      body.dataset.drawn = String(k);
      body.dataset.faces = String(f);
      facesStale = false;
    }

    let draws = 0;
    function draw() {
      if (facesStale) updateModules();
      renderer.render(scene, camera);
      dirty = false;
      body.dataset.draws = String(++draws);
    }

    // ---------------------------------------------------------------- chart
    // the curves are drawn once (again on resize and toggles); playing only moves the cursor element and
    // changes the legend's numbers, so that a picture costs no canvas drawing and no layout
    const chart = $('chart'), chartCtx = chart.getContext('2d'), cursor = $('cursor');
    const LINE_COLOURS = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f', '#bcbd22', '#17becf'];
    const seriesNames = Object.keys(meta.series);
    const seriesOn = seriesNames.map((name) => meta.metric_names.length ? meta.metric_names.includes(name) : true);
    const legend = $('legend');
    const legendValues = seriesNames.map((name, k) => {
      const row = document.createElement('div');
      row.innerHTML = `<span class="swatch"></span><span class="name"></span> <span class="value"></span>`;
      row.querySelector('.swatch').style.background = LINE_COLOURS[k % LINE_COLOURS.length];
      row.querySelector('.name').textContent = name;
      row.title = `${name}: click to show or hide`;
      row.classList.toggle('off', !seriesOn[k]);
      row.addEventListener('click', () => { seriesOn[k] = !seriesOn[k]; row.classList.toggle('off', !seriesOn[k]); drawChart(); });
      legend.appendChild(row);
      return row.querySelector('.value');
    });

    /** Where frame's cycle is on the chart, in pixels from its left, in a chart width pixels wide. */
    function chartX(frame, width) { return T > 1 ? 4 + (width - 8) * frame / (T - 1) : width / 2; }

    function drawChart() {
      const ratio = window.devicePixelRatio || 1;
      const width = Math.max(1, Math.round(chart.clientWidth * ratio)), height = Math.max(1, Math.round(chart.clientHeight * ratio));
      chart.width = width; chart.height = height;
      const ctx = chartCtx;
      ctx.fillStyle = '#ffffff'; ctx.fillRect(0, 0, width, height);
      seriesNames.forEach((name, k) => {
        if (!seriesOn[k]) return;
        const values = meta.series[name];
        let vlo = Infinity, vhi = -Infinity;
        for (const v of values) if (v !== null) { vlo = Math.min(vlo, v); vhi = Math.max(vhi, v); }
        if (!isFinite(vlo)) return;
        const span = vhi - vlo || 1;
        ctx.strokeStyle = LINE_COLOURS[k % LINE_COLOURS.length]; ctx.lineWidth = 1.5 * (window.devicePixelRatio || 1);
        ctx.beginPath();
        let pen = false;
        values.forEach((v, t) => {
          if (v === null) { pen = false; return; }
          const x = chartX(t, width), y = height - 6 - (height - 12) * (v - vlo) / span;
          if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
          pen = true;
        });
        ctx.stroke();
      });
      chartWidth = width / ratio;
      moveCursor();
    }

    let chartWidth = 1;  // CSS pixels, as of the last drawChart
    function moveCursor() {
      cursor.style.transform = `translateX(${chartX(episode.frame, chartWidth).toFixed(1)}px)`;
      seriesNames.forEach((name, k) => {
        const v = meta.series[name][episode.frame];
        setText(legendValues[k], v === null ? '–' : (Number.isInteger(v) ? String(v) : v.toPrecision(3)));
      });
    }

    /** Change an element's text only when it differs (an unchanged text then costs no layout). */
    function setText(element, text) { if (element.textContent !== text) element.textContent = text; }

    function seekFromChart(event) {
      const rect = chart.getBoundingClientRect();
      const share = (event.clientX - rect.left - 4) / Math.max(1, rect.width - 8);
      seek(Math.round(share * (T - 1)));
    }
    chart.addEventListener('pointerdown', (e) => { chart.setPointerCapture(e.pointerId); seekFromChart(e); });
    chart.addEventListener('pointermove', (e) => { if (e.buttons & 1) seekFromChart(e); });

    // ---------------------------------------------------------------- modes panel
    const modeCounts = names.map(() => 0);
    const countCells = names.map((name, m) => {
      const label = document.createElement('label');
      label.innerHTML = `<input type="checkbox" checked> <span class="swatch"></span><span class="name"></span><span class="count"></span>`;
      label.querySelector('.swatch').style.background = meta.mode_colours[m];
      label.querySelector('.name').textContent = name;
      label.querySelector('input').addEventListener('change', (e) => { shown[m] = e.target.checked; refresh(); });
      $('modes').appendChild(label);
      return label.querySelector('.count');
    });

    // ---------------------------------------------------------------- cut-away
    const cutAxis = $('cut-axis'), cutAt = $('cut-at'), cutFlip = $('cut-flip');
    function updateCut() {
      const axis = cutAxis.value === '' ? -1 : Number(cutAxis.value);
      cutAt.disabled = axis < 0;
      clipping.length = 0;
      if (axis >= 0) {
        const sign = cutFlip.checked ? 1 : -1;
        const normal = new THREE.Vector3(); normal.setComponent(axis, sign);
        cut.set(normal, -sign * Number(cutAt.value));
        clipping.push(cut);
        $('cut-readout').textContent = `showing ${'xyz'[axis]} ${cutFlip.checked ? '≥' : '≤'} ${cutAt.value}`;
      } else {
        $('cut-readout').textContent = '';
      }
      facesStale = true;
      requestDraw();
    }
    cutAxis.addEventListener('change', () => {
      const axis = Number(cutAxis.value);
      if (cutAxis.value !== '') {
        cutAt.min = String(lo[axis] - 1); cutAt.max = String(hi[axis] + 1);
        cutAt.value = String(Math.round((lo[axis] + hi[axis]) / 2));
      }
      updateCut();
    });
    cutAt.addEventListener('input', updateCut);
    cutFlip.addEventListener('change', updateCut);

    // ---------------------------------------------------------------- inspect
    const raycaster = new THREE.Raycaster();
    function pickAt(clientX, clientY) {
      const rect = canvas.getBoundingClientRect();
      const ndc = new THREE.Vector2(2 * (clientX - rect.left) / rect.width - 1, 1 - 2 * (clientY - rect.top) / rect.height);
      raycaster.setFromCamera(ndc, camera);
      const hits = raycaster.intersectObject(modules, false).filter((h) => clipping.every((p) => p.distanceToPoint(h.point) >= -1e-6));
      select(hits.length ? faceModule[Math.floor(hits[0].faceIndex / 2)] : -1);
    }

    function select(id) {
      picked = id;
      body.dataset.picked = String(id);
      marker.visible = id >= 0;
      showPicked();
      updateModules();
      requestDraw();
    }

    function showPicked() {
      const box = $('picked');
      if (picked < 0) { box.textContent = 'Click a module to see its id, mode and scents.'; return; }
      const p = episode.positions, i = picked;
      const scents = [];
      for (let ch = 0; ch < meta.n_channels; ch++) {
        const s = episode.scents[ch * N + i];
        scents.push(s < 0 ? 'none' : String(s));
      }
      const rows = [['id', String(i)], ['mode', names[episode.modes[i]]], ['site', `${p[3 * i]}, ${p[3 * i + 1]}, ${p[3 * i + 2]}`],
        ['scents', scents.join(', ') || '–'], ['anchored', anchored[i] ? 'yes' : 'no'], ['cycle', String(meta.cycles[episode.frame])]];
      box.innerHTML = '<table></table>';
      for (const [key, value] of rows) {
        const tr = box.firstChild.insertRow();
        tr.insertCell().textContent = key;
        tr.insertCell().textContent = value;
        tr.dataset.key = key;
      }
    }

    let downAt = null;
    canvas.addEventListener('pointerdown', (e) => { downAt = [e.clientX, e.clientY]; });
    canvas.addEventListener('pointerup', (e) => {
      if (downAt && Math.hypot(e.clientX - downAt[0], e.clientY - downAt[1]) < 4 && e.button === 0) pickAt(e.clientX, e.clientY);
      downAt = null;
    });

    // ---------------------------------------------------------------- timeline and playback
    const timeline = $('timeline'), playButton = $('play'), speedSelect = $('speed'), cycleReadout = $('cycle-readout');
    timeline.max = String(T - 1);
    const SPEEDS = [1, 2, 5, 10, 20, 50, 100, 200, 500];
    for (const s of SPEEDS) speedSelect.add(new Option(`${s} cycles/s`, String(s)));
    speedSelect.value = String(SPEEDS.reduce((best, s) => (Math.abs(Math.log(s * 20 / T)) < Math.abs(Math.log(best * 20 / T)) ? s : best)));
    let playing = false, carry = 0, lastTime = null;

    function refresh() {
      modeCounts.fill(0);
      for (let i = 0; i < N; i++) modeCounts[episode.modes[i]]++;
      countCells.forEach((cell, m) => setText(cell, String(modeCounts[m])));
      updateModules();
      const cycle = meta.cycles[episode.frame];
      timeline.value = String(episode.frame);
      setText(cycleReadout, `cycle ${cycle} / ${meta.cycles[T - 1]}`);
      body.dataset.frame = String(episode.frame);
      body.dataset.cycle = String(cycle);
      document.title = errors.length ? document.title : `proteo · ${meta.task_id} · cycle ${cycle} / ${meta.cycles[T - 1]} · ${N} modules`;
      if (picked >= 0) showPicked();
      moveCursor();
      requestDraw();
    }

    function seek(frame) { episode.seek(frame); refresh(); }
    function setPlaying(on) {
      playing = on && T > 1;
      if (playing && episode.frame >= T - 1) seek(0);
      carry = 0; lastTime = null;
      playButton.textContent = playing ? '||' : '▶';
    }

    timeline.addEventListener('input', () => { setPlaying(false); seek(Number(timeline.value)); });
    playButton.addEventListener('click', () => setPlaying(!playing));
    $('first').addEventListener('click', () => { setPlaying(false); seek(0); });
    $('last').addEventListener('click', () => { setPlaying(false); seek(T - 1); });
    $('back').addEventListener('click', () => { setPlaying(false); seek(episode.frame - 1); });
    $('forward').addEventListener('click', () => { setPlaying(false); seek(episode.frame + 1); });
    window.addEventListener('keydown', (e) => {
      if (e.target instanceof HTMLSelectElement || (e.target instanceof HTMLInputElement && e.target.type !== 'range' && e.target.type !== 'checkbox')) return;
      const keys = { ' ': () => setPlaying(!playing), ArrowRight: () => { setPlaying(false); seek(episode.frame + 1); },
        ArrowLeft: () => { setPlaying(false); seek(episode.frame - 1); }, Home: () => { setPlaying(false); seek(0); },
        End: () => { setPlaying(false); seek(T - 1); } };
      if (keys[e.key]) { keys[e.key](); e.preventDefault(); }
    });

    function tick(now) {
      if (playing) {
        if (lastTime !== null) carry += (now - lastTime) / 1000 * Number(speedSelect.value);
        lastTime = now;
        const steps = Math.floor(carry);
        if (steps > 0) {
          carry -= steps;
          seek(Math.min(T - 1, episode.frame + steps));
          if (episode.frame >= T - 1) setPlaying(false);
        }
      }
      if (dirty) draw();
      requestAnimationFrame(tick);
    }

    function resize() {
      const width = Math.max(1, canvas.clientWidth), height = Math.max(1, canvas.clientHeight);
      renderer.setSize(width, height, false);
      camera.aspect = width / height;
      camera.updateProjectionMatrix();
      drawChart();
      requestDraw();
    }
    new ResizeObserver(resize).observe($('stage'));

    function openAt(hash) {
      const match = /^#(frame|cycle)=(-?\d+)$/.exec(hash || '');
      if (!match) return false;
      const value = Number(match[2]);
      if (match[1] === 'frame') seek(value < 0 ? T + value : value);
      else { const f = meta.cycles.indexOf(value); seek(f >= 0 ? f : (value < meta.cycles[0] ? 0 : T - 1)); }
      return true;
    }
    window.addEventListener('hashchange', () => { setPlaying(false); openAt(location.hash); });

    resize();
    frameView();
    if (!openAt(location.hash)) seek(0);
    draw();

    window.proteoViewer = {
      seek, step: (k) => seek(episode.frame + (k === undefined ? 1 : k)),
      play: () => setPlaying(true), pause: () => setPlaying(false),
      render: () => { draw(); },
      /** Screen position (CSS pixels in the page) of module id's centre at the current frame. */
      project: (id) => {
        const p = episode.positions, v = new THREE.Vector3(p[3 * id], p[3 * id + 1], p[3 * id + 2]).project(camera);
        const rect = canvas.getBoundingClientRect();
        return [rect.left + (v.x + 1) / 2 * rect.width, rect.top + (1 - v.y) / 2 * rect.height];
      },
      pick: pickAt, showMode: (m, on) => { shown[m] = on; refresh(); },
      state: () => ({ frame: episode.frame, cycle: meta.cycles[episode.frame], frames: T, modules: N,
        drawn: drawnCount, faces: faceCount, playing, modeCounts: modeCounts.slice(), errors: errors.slice() }),
      three: { renderer, scene, camera, controls },
    };
    body.dataset.loadMs = performance.now().toFixed(1);
    body.dataset.ready = '1';
    requestAnimationFrame(tick);
  }

  start().catch((err) => reportError(err && err.stack ? err.message : err));
})();
