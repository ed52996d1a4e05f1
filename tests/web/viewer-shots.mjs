#!/usr/bin/env node
// Screenshots a published viewer page (<model-viewer>) from fixed cameras, in
// headless Chromium, and writes what camera model-viewer actually used, so a
// C++ test can render the same views with its own pinhole renderer.
//
// usage: node viewer-shots.mjs --site DIR --page REL/index.html --out OUTDIR
//            [--chromium /usr/bin/chromium] [--width 640] [--height 480]
//            [--timeout 60]
//
// It serves DIR on an ephemeral 127.0.0.1 port (node:http), opens the page,
// waits for the first <model-viewer>'s `load` event, then for each of 4 orbits
// jumps the camera there and screenshots exactly the element's WIDTHxHEIGHT CSS
// px (device scale factor 1) into OUTDIR/shot-K.png. OUTDIR/shots.json
// describes every shot (see CONVENTIONS below).
//
// It fails (exit 1, message on stderr) on: the model never loading within the
// timeout, a model-viewer `error` event, an uncaught page error, a console
// error, a failed request or an HTTP status >= 400, and ANY request to a
// non-localhost URL (such requests are blocked): a published page must work
// offline. Usage errors exit 2.
//
// The page decides tone mapping, exposure, lighting and so on; this script only
// pins the layout (element fixed at the top left, WIDTHxHEIGHT, white page and
// element background), turns off auto-rotate and the interaction prompt, pins
// the render scale to 1, and widens the camera limits so the requested orbit is
// not clamped. The page's own settings are reported in shots.json.
//
// Packages come from $CAROUSEL_WEB_MODULES, else web/node_modules, else NODE_PATH.
// CAROUSEL_SHOTS_DEBUG=1 adds the request timeline to a failure message.
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import zlib from 'node:zlib';
import {requireWeb} from './web-modules.mjs';

const CONVENTIONS = [
  'All coordinates are model-viewer model coordinates = the glTF scene frame (metres, +Y up); ' +
      'our Z-up world maps to it by the node rotation -90deg about X: glTF (x, y, z) = world (x, z, -y).',
  'Camera centre C = target + radius * (sin(phi) sin(theta), cos(phi), sin(phi) cos(theta)); ' +
      'it looks at target with no roll (camera up lies in the plane of +Y and the view direction). ' +
      'theta = 0 looks from +Z (world -Y) towards -Z; theta = 90deg looks from +X.',
  'Projection: three.js PerspectiveCamera; fov_deg is the VERTICAL field of view actually used ' +
      '(getFieldOfView()), aspect = width / height, square pixels, principal point at the image centre: ' +
      'f_px = (height / 2) / tan(fov_deg / 2); pixel u = width/2 + f_px * x_c / -z_c, v = height/2 - f_px * y_c / -z_c ' +
      '(camera frame x right, y up, looking down -z; u right, v down, pixel centres at +0.5).',
  'The model turntable yaw (auto-rotate) is reset to 0 before the shots; turntable_yaw_rad reports it.',
];

const ORBITS = [
  {theta: 0, phi: 75},
  {theta: 90, phi: 75},
  {theta: 180, phi: 75},
  {theta: 270, phi: 60},
];
const FOV_DEG = 30;
// Camera distance: the bounding box's circumscribed sphere fills this fraction
// of the vertical field of view (1/RADIUS_MARGIN of the half-angle's sine).
const RADIUS_MARGIN = 1.15;

const MIME = {
  '.html': 'text/html; charset=utf-8',
  '.htm': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8',
  '.cjs': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8',
  '.json': 'application/json',
  '.map': 'application/json',
  '.glb': 'model/gltf-binary',
  '.gltf': 'model/gltf+json',
  '.bin': 'application/octet-stream',
  '.png': 'image/png',
  '.jpg': 'image/jpeg',
  '.jpeg': 'image/jpeg',
  '.webp': 'image/webp',
  '.avif': 'image/avif',
  '.ktx2': 'image/ktx2',
  '.hdr': 'image/vnd.radiance',
  '.svg': 'image/svg+xml',
  '.ico': 'image/x-icon',
  '.wasm': 'application/wasm',
  '.usdz': 'model/vnd.usdz+zip',
  '.txt': 'text/plain; charset=utf-8',
};

// ---------------------------------------------------------------- arguments
function usage(msg) {
  if (msg) process.stderr.write(`viewer-shots: ${msg}\n`);
  process.stderr.write('usage: node viewer-shots.mjs --site DIR --page REL/index.html --out OUTDIR ' +
      '[--chromium /usr/bin/chromium] [--width 640] [--height 480] [--timeout 60]\n');
  process.exit(2);
}

function parseArgs(argv) {
  const opt = {chromium: process.env.CHROMIUM || '/usr/bin/chromium', width: 640, height: 480, timeout: 60};
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    const m = /^--([a-z]+)(?:=(.*))?$/.exec(a);
    if (!m) usage(`unexpected argument ${a}`);
    const key = m[1];
    if (!['site', 'page', 'out', 'chromium', 'width', 'height', 'timeout'].includes(key)) usage(`unknown option ${a}`);
    const val = m[2] !== undefined ? m[2] : argv[++i];
    if (val === undefined) usage(`${a} needs a value`);
    opt[key] = val;
  }
  for (const k of ['site', 'page', 'out']) if (!opt[k]) usage(`--${k} is required`);
  for (const [k, lo, hi] of [['width', 16, 8192], ['height', 16, 8192], ['timeout', 1, 3600]]) {
    const n = Number(opt[k]);
    if (!Number.isInteger(n) || n < lo || n > hi) usage(`--${k} must be an integer in [${lo}, ${hi}] (got ${opt[k]})`);
    opt[k] = n;
  }
  opt.site = path.resolve(opt.site);
  opt.out = path.resolve(opt.out);
  if (!fs.existsSync(opt.site) || !fs.statSync(opt.site).isDirectory()) usage(`--site ${opt.site} is not a directory`);
  const pageFile = path.resolve(opt.site, opt.page);
  if (!pageFile.startsWith(opt.site + path.sep) || !fs.existsSync(pageFile) || !fs.statSync(pageFile).isFile()) {
    usage(`--page ${opt.page} is not a file under ${opt.site}`);
  }
  if (!fs.existsSync(opt.chromium)) usage(`chromium not found at ${opt.chromium} (apt-get install chromium)`);
  opt.page = path.relative(opt.site, pageFile).split(path.sep).join('/');
  return opt;
}

// ---------------------------------------------------------------- static server
function startServer(root, log) {
  const server = http.createServer((req, res) => {
    const entry = {method: req.method, path: req.url, status: 0};
    log.push(entry);
    const send = (status, headers, body) => {
      entry.status = status;
      res.writeHead(status, {'Cache-Control': 'no-store', 'X-Content-Type-Options': 'nosniff', ...headers});
      res.end(req.method === 'HEAD' ? undefined : body);
    };
    if (req.method !== 'GET' && req.method !== 'HEAD') return send(405, {'Content-Type': 'text/plain'}, 'method not allowed\n');
    let rel;
    try {
      rel = decodeURIComponent(new URL(req.url, 'http://localhost').pathname);
    } catch {
      return send(400, {'Content-Type': 'text/plain'}, 'bad url\n');
    }
    let file = path.resolve(root, '.' + rel);
    if (file !== root && !file.startsWith(root + path.sep)) return send(403, {'Content-Type': 'text/plain'}, 'forbidden\n');
    try {
      if (fs.statSync(file).isDirectory()) file = path.join(file, 'index.html');
      const body = fs.readFileSync(file);
      const type = MIME[path.extname(file).toLowerCase()] || 'application/octet-stream';
      send(200, {'Content-Type': type, 'Content-Length': body.length}, body);
    } catch {
      send(404, {'Content-Type': 'text/plain'}, 'not found\n');
    }
  });
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(0, '127.0.0.1', () => resolve(server));
  });
}

// ---------------------------------------------------------------- PNG check
// Minimal decoder for the 8-bit RGB/RGBA non-interlaced PNGs Chromium writes;
// returns the fraction of pixels that are not (near) white.
function nonWhiteFraction(png) {
  let off = 8, width = 0, height = 0, channels = 0;
  const idat = [];
  while (off < png.length) {
    const len = png.readUInt32BE(off);
    const type = png.toString('ascii', off + 4, off + 8);
    const data = png.subarray(off + 8, off + 8 + len);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      const depth = data[8], colour = data[9], interlace = data[12];
      if (depth !== 8 || interlace !== 0 || (colour !== 2 && colour !== 6)) return null;
      channels = colour === 2 ? 3 : 4;
    } else if (type === 'IDAT') {
      idat.push(data);
    }
    off += 12 + len;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const prev = Buffer.alloc(stride), cur = Buffer.alloc(stride);
  let nonWhite = 0;
  for (let y = 0; y < height; y++) {
    const ft = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let i = 0; i < stride; i++) {
      const a = i >= channels ? cur[i - channels] : 0, b = prev[i], c = i >= channels ? prev[i - channels] : 0;
      let p;
      switch (ft) {
        case 0: p = 0; break;
        case 1: p = a; break;
        case 2: p = b; break;
        case 3: p = (a + b) >> 1; break;
        case 4: {
          const pa = Math.abs(b - c), pb = Math.abs(a - c), pc = Math.abs(a + b - 2 * c);
          p = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
          break;
        }
        default: return null;
      }
      cur[i] = (line[i] + p) & 0xff;
    }
    for (let x = 0; x < width; x++) {
      const o = x * channels;
      if (cur[o] < 250 || cur[o + 1] < 250 || cur[o + 2] < 250) nonWhite++;
    }
    cur.copy(prev);
  }
  return nonWhite / (width * height);
}

// ---------------------------------------------------------------- page hooks
// Runs in the page before any of its scripts.
function pageHook(width, height) {
  const state = {loadAt: null, errorAt: null, error: null, original: null, styled: false};
  window.__carouselShots = state;
  const onLoad = (e) => {
    if (e.target && e.target.localName === 'model-viewer' && state.loadAt === null) state.loadAt = performance.now();
  };
  const onError = (e) => {
    if (e.target && e.target.localName === 'model-viewer' && state.error === null) {
      state.errorAt = performance.now();
      const d = e.detail || {};
      state.error = `${d.type || 'error'}: ${d.sourceError ? String(d.sourceError.stack || d.sourceError) : ''}`;
    }
  };
  document.addEventListener('load', onLoad, true);
  document.addEventListener('error', onError, true);
  const style = () => {
    const mv = document.querySelector('model-viewer');
    if (!mv || state.styled) return;
    state.styled = true;
    const attr = (n) => mv.getAttribute(n);
    state.original = {
      src: attr('src'),
      'tone-mapping': attr('tone-mapping'),
      exposure: attr('exposure'),
      'environment-image': attr('environment-image'),
      'skybox-image': attr('skybox-image'),
      'shadow-intensity': attr('shadow-intensity'),
      'auto-rotate': mv.hasAttribute('auto-rotate'),
      'camera-controls': mv.hasAttribute('camera-controls'),
      'camera-orbit': attr('camera-orbit'),
      'camera-target': attr('camera-target'),
      'field-of-view': attr('field-of-view'),
      'interaction-prompt': attr('interaction-prompt'),
      orientation: attr('orientation'),
      scale: attr('scale'),
      poster: attr('poster'),
      loading: attr('loading'),
      reveal: attr('reveal'),
    };
    document.documentElement.style.background = '#ffffff';
    if (document.body) {
      document.body.style.background = '#ffffff';
    }
    const s = mv.style;
    s.setProperty('position', 'fixed', 'important');
    s.setProperty('left', '0px', 'important');
    s.setProperty('top', '0px', 'important');
    s.setProperty('margin', '0px', 'important');
    s.setProperty('padding', '0px', 'important');
    s.setProperty('border', '0px none', 'important');
    s.setProperty('box-sizing', 'content-box', 'important');
    s.setProperty('width', `${width}px`, 'important');
    s.setProperty('height', `${height}px`, 'important');
    s.setProperty('max-width', 'none', 'important');
    s.setProperty('max-height', 'none', 'important');
    s.setProperty('transform', 'none', 'important');
    s.setProperty('z-index', '2147483647', 'important');
    s.setProperty('background-color', '#ffffff', 'important');
    mv.removeAttribute('auto-rotate');
    mv.setAttribute('interaction-prompt', 'none');
  };
  document.addEventListener('DOMContentLoaded', style);
  // In case the element is added by script after DOMContentLoaded.
  new MutationObserver(style).observe(document, {childList: true, subtree: true});
}

// ---------------------------------------------------------------- main
const t0 = Date.now();
const opt = parseArgs(process.argv.slice(2));
let browser = null;
let server = null;
let userDataDir = null;

async function main() {
  const puppeteer = requireWeb('puppeteer-core');
  fs.mkdirSync(opt.out, {recursive: true});
  for (const f of fs.readdirSync(opt.out)) {
    if (/^shot-\d+\.png$/.test(f) || f === 'shots.json') fs.rmSync(path.join(opt.out, f));
  }

  const serverLog = [];
  server = await startServer(opt.site, serverLog);
  const port = server.address().port;
  const origin = `http://127.0.0.1:${port}`;
  const pageUrl = `${origin}/${opt.page.split('/').map(encodeURIComponent).join('/')}`;

  userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'carousel-shots-'));
  browser = await puppeteer.launch({
    executablePath: opt.chromium,
    headless: true,
    userDataDir,
    defaultViewport: {width: opt.width, height: opt.height, deviceScaleFactor: 1},
    protocolTimeout: (opt.timeout + 60) * 1000,
    args: [
      '--no-sandbox',
      '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader',
      '--ignore-gpu-blocklist',
      '--disable-dev-shm-usage',
      '--force-color-profile=srgb',
      '--hide-scrollbars',
      `--window-size=${opt.width},${opt.height}`,
      '--no-proxy-server',
      // Belt and braces: no host name resolves, so nothing can leave the machine.
      '--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE localhost, EXCLUDE 127.0.0.1',
      '--disable-background-networking',
      '--disable-component-update',
      '--disable-domain-reliability',
      '--disable-sync',
      '--no-pings',
      '--disable-background-timer-throttling',
      '--disable-renderer-backgrounding',
      '--disable-backgrounding-occluded-windows',
    ],
  });
  const chromiumVersion = await browser.version();

  const page = await browser.newPage();
  const problems = [];
  const consoleErrors = [];
  const consoleWarnings = [];
  const requests = [];
  const external = [];
  const isLocal = (u) => {
    if (u.startsWith('data:') || u.startsWith('blob:')) return true;
    try {
      const url = new URL(u);
      return url.origin === origin;
    } catch {
      return false;
    }
  };
  // Chromium asks for /favicon.ico by itself; a missing one is not the page's fault.
  const isFavicon = (u) => u === `${origin}/favicon.ico`;
  await page.setRequestInterception(true);
  const debugEvents = [];
  const dbg = (what, req, more = '') => {
    if (process.env.CAROUSEL_SHOTS_DEBUG) {
      debugEvents.push(`${Date.now() - t0}ms ${what} ${req.resourceType()} ${req.url().replace(origin, '')} ${more}`);
    }
  };
  page.on('requestfinished', (req) => dbg('finished', req));
  page.on('request', (req) => {
    dbg('request', req, `nav=${req.isNavigationRequest()} initiator=${JSON.stringify(req.initiator() && req.initiator().type)}`);
    const u = req.url();
    if (!isLocal(u)) {
      external.push(u);
      problems.push(`request to a non-local URL (blocked): ${u}`);
      req.abort('blockedbyclient').catch(() => {});
      return;
    }
    req.continue().catch(() => {});
  });
  page.on('response', (res) => {
    const u = res.url();
    if (u.startsWith('data:') || u.startsWith('blob:')) return;
    requests.push({url: u.startsWith(origin) ? u.slice(origin.length) : u, status: res.status(),
      type: res.headers()['content-type'] || null});
    if (res.status() >= 400 && !isFavicon(u)) problems.push(`HTTP ${res.status()} for ${u}`);
  });
  // Under load Chromium sometimes reports a fetch as net::ERR_ABORTED although
  // the whole response was delivered and used (seen for the GLB: the server sent
  // 200 and the model loaded). Such an abort is only a problem if the server did
  // not answer that URL with 200; checkAborted() decides once loading is over.
  const aborted = [];
  page.on('requestfailed', (req) => {
    dbg('failed', req, req.failure() && req.failure().errorText);
    if (!isLocal(req.url())) return;  // already reported above
    const why = req.failure() ? req.failure().errorText : '?';
    if (why === 'net::ERR_ABORTED' && req.url().startsWith(origin)) {
      aborted.push(req.url());
      return;
    }
    problems.push(`request failed: ${req.url()} (${why})`);
  });
  const checkAborted = () => {
    while (aborted.length) {
      const u = aborted.shift();
      const p = u.slice(origin.length);
      if (!serverLog.some((e) => e.path === p && e.status === 200)) problems.push(`request failed: ${u} (net::ERR_ABORTED)`);
      else abortedButServed.push(p);
    }
  };
  const abortedButServed = [];
  page.on('pageerror', (err) => problems.push(`page error: ${err && err.message ? err.message : err}`));
  page.on('console', (msg) => {
    const loc = msg.location();
    const where = loc && loc.url ? ` (${loc.url.replace(origin, '')}${loc.lineNumber != null ? ':' + loc.lineNumber : ''})` : '';
    if (msg.type() === 'error' && !(loc && loc.url && isFavicon(loc.url))) {
      consoleErrors.push(msg.text() + where);
      problems.push(`console error: ${msg.text()}${where}`);
    } else if (msg.type() === 'warn' || msg.type() === 'warning') {
      consoleWarnings.push(msg.text() + where);
    }
  });
  page.on('error', (err) => problems.push(`page crashed: ${err.message}`));

  await page.evaluateOnNewDocument(pageHook, opt.width, opt.height);

  const failNow = (msg) => {
    let extra = problems.length ? `\n  also: ${problems.join('\n  also: ')}` : '';
    if (process.env.CAROUSEL_SHOTS_DEBUG) {
      extra += `\n  events:\n    ${debugEvents.join('\n    ')}`;
      extra += `\n  server saw: ${serverLog.map((e) => `${e.method} ${e.path} ${e.status}`).join(', ')}`;
    }
    throw new Error(`${opt.page}: ${msg}${extra}`);
  };

  try {
    await page.goto(pageUrl, {waitUntil: 'load', timeout: opt.timeout * 1000});
  } catch (e) {
    failNow(`page did not load: ${e.message}`);
  }

  // The element and its definition.
  const deadline = Date.now() + opt.timeout * 1000;
  const left = () => Math.max(1, deadline - Date.now());
  try {
    await page.waitForFunction(() => !!document.querySelector('model-viewer'), {timeout: left(), polling: 100});
  } catch {
    failNow('no <model-viewer> element in the page');
  }
  try {
    await page.waitForFunction(() => !!customElements.get('model-viewer'), {timeout: left(), polling: 100});
  } catch {
    failNow('<model-viewer> was never defined: its script did not load or run');
  }

  // The model's load event (or its error event).
  try {
    await page.waitForFunction(() => {
      const s = window.__carouselShots;
      return s.loadAt !== null || s.error !== null;
    }, {timeout: left(), polling: 50});
  } catch {
    const src = await page.evaluate(() => document.querySelector('model-viewer').getAttribute('src')).catch(() => '?');
    const what = src === null ? '<model-viewer> (it has no src attribute)' : `<model-viewer src="${src}">`;
    failNow(`${what} did not fire 'load' within ${opt.timeout} s`);
  }
  const state = await page.evaluate(() => ({...window.__carouselShots}));
  if (state.error) failNow(`<model-viewer> fired 'error': ${state.error}`);
  checkAborted();
  if (problems.length) failNow('problems while loading');

  // Settle: poster gone, model visible, progress bar faded, full render scale.
  const settle = await page.evaluate(async (timeoutMs) => {
    const mv = document.querySelector('model-viewer');
    const MV = customElements.get('model-viewer');
    MV.minimumRenderScale = 1;
    mv.autoRotate = false;
    mv.interactionPrompt = 'none';
    if (typeof mv.resetTurntableRotation === 'function') mv.resetTurntableRotation(0);
    const end = performance.now() + timeoutMs;
    const frame = () => new Promise((r) => requestAnimationFrame(() => r()));
    const barHidden = () => {
      const bar = mv.shadowRoot && mv.shadowRoot.querySelector('#default-progress-bar > .bar');
      if (!bar) return true;
      const slot = mv.shadowRoot.querySelector('slot[name="progress-bar"]');
      if (slot && slot.assignedNodes().length > 0) return true;  // page replaced the bar
      return getComputedStyle(bar).opacity === '0' || bar.getBoundingClientRect().width === 0;
    };
    const posterHidden = () => {
      const p = mv.shadowRoot && mv.shadowRoot.querySelector('.slot.poster');
      return !p || !p.classList.contains('show');
    };
    while (performance.now() < end) {
      if (mv.modelIsVisible && barHidden() && posterHidden()) break;
      await frame();
    }
    return {visible: mv.modelIsVisible, bar: barHidden(), poster: posterHidden(),
      dims: mv.getDimensions(), center: mv.getBoundingBoxCenter(),
      toneMapping: mv.toneMapping, exposure: mv.exposure, environmentImage: mv.environmentImage,
      skyboxImage: mv.skyboxImage, shadowIntensity: mv.shadowIntensity,
      rect: mv.getBoundingClientRect().toJSON(), dpr: window.devicePixelRatio};
  }, Math.min(left(), 10000));
  if (!settle.visible) failNow('model loaded but never became visible (modelIsVisible stayed false)');
  if (!settle.poster) failNow('the poster never went away');
  if (!settle.bar) failNow('the loading bar never went away');
  const r = settle.rect;
  if (r.x !== 0 || r.y !== 0 || r.width !== opt.width || r.height !== opt.height || settle.dpr !== 1) {
    failNow(`could not size <model-viewer> to ${opt.width}x${opt.height} at (0,0), dpr 1: got ` +
        `${r.width}x${r.height} at (${r.x},${r.y}), dpr ${settle.dpr}`);
  }

  const d = settle.dims, c = settle.center;
  const halfDiag = 0.5 * Math.hypot(d.x, d.y, d.z);
  if (!(halfDiag > 0) || !Number.isFinite(halfDiag)) failNow(`model has an empty bounding box (${JSON.stringify(d)})`);
  const round = (x) => Number(x.toPrecision(7));
  const radius = round(RADIUS_MARGIN * halfDiag / Math.sin((FOV_DEG / 2) * Math.PI / 180));
  const target = [round(c.x), round(c.y), round(c.z)];

  const shots = [];
  for (let k = 0; k < ORBITS.length; k++) {
    const {theta, phi} = ORBITS[k];
    const got = await page.evaluate(async (theta, phi, radius, target, fov) => {
      const mv = document.querySelector('model-viewer');
      const frame = () => new Promise((r) => requestAnimationFrame(() => r()));
      // Limits wide enough that nothing is clamped.
      mv.minCameraOrbit = 'auto auto 0m';
      mv.maxCameraOrbit = `auto auto ${radius}m`;
      mv.minFieldOfView = '1deg';
      mv.maxFieldOfView = '120deg';
      mv.cameraTarget = `${target[0]}m ${target[1]}m ${target[2]}m`;
      mv.cameraOrbit = `${theta}deg ${phi}deg ${radius}m`;
      mv.fieldOfView = `${fov}deg`;
      await mv.updateComplete;
      const changed = new Promise((r) => {
        mv.addEventListener('camera-change', () => r(true), {once: true});
        setTimeout(() => r(false), 2000);
      });
      mv.jumpCameraToGoal();
      await mv.updateComplete;
      const sawChange = await changed;
      // The renderer draws in its rAF callback; two more frames make sure the
      // frame after the jump has been drawn and composited.
      await frame();
      await frame();
      await frame();
      const o = mv.getCameraOrbit(), t = mv.getCameraTarget();
      return {sawChange, theta: o.theta, phi: o.phi, radius: o.radius, target: [t.x, t.y, t.z],
        fov: mv.getFieldOfView(), yaw: mv.turntableRotation ?? 0,
        minFov: mv.getMinimumFieldOfView(), maxFov: mv.getMaximumFieldOfView(),
        idealAspect: typeof mv.getIdealAspect === 'function' ? mv.getIdealAspect() : null};
    }, theta, phi, radius, target, FOV_DEG);

    const rad = Math.PI / 180;
    const dTheta = Math.abs(Math.atan2(Math.sin(got.theta - theta * rad), Math.cos(got.theta - theta * rad)));
    const off = Math.max(dTheta, Math.abs(got.phi - phi * rad), Math.abs(got.radius - radius) / radius,
        ...got.target.map((v, i) => Math.abs(v - target[i]) / radius));
    if (off > 1e-5) {
      failNow(`camera did not reach orbit ${theta}deg ${phi}deg ${radius}m target ${target.join(' ')}: ` +
          `model-viewer reports ${got.theta}rad ${got.phi}rad ${got.radius}m target ${got.target.join(' ')}`);
    }
    if (Math.abs(got.yaw) > 1e-9) failNow(`turntable yaw is ${got.yaw} rad, not 0`);

    const file = `shot-${k}.png`;
    const png = Buffer.from(await page.screenshot({
      type: 'png', clip: {x: 0, y: 0, width: opt.width, height: opt.height}, captureBeyondViewport: false,
    }));
    fs.writeFileSync(path.join(opt.out, file), png);
    const nonWhite = nonWhiteFraction(png);
    if (nonWhite !== null && nonWhite === 0) failNow(`${file} is all white: the model was not drawn`);

    const st = Math.sin(got.theta), ct = Math.cos(got.theta), sp = Math.sin(got.phi), cp = Math.cos(got.phi);
    const pos = [got.target[0] + got.radius * sp * st, got.target[1] + got.radius * cp,
      got.target[2] + got.radius * sp * ct];
    shots.push({
      file,
      theta_deg: theta,
      phi_deg: phi,
      radius_m: radius,
      target_m: target,
      fov_deg: got.fov,
      field_of_view_attr_deg: FOV_DEG,
      width: opt.width,
      height: opt.height,
      reported: {
        camera_orbit: {theta_rad: got.theta, phi_rad: got.phi, radius_m: got.radius},
        camera_target_m: got.target,
        field_of_view_deg: got.fov,
        min_field_of_view_deg: got.minFov,
        max_field_of_view_deg: got.maxFov,
        ideal_aspect: got.idealAspect,
        camera_change_event: got.sawChange,
      },
      camera_position_m: pos,
      turntable_yaw_rad: got.yaw,
      nonwhite_fraction: nonWhite === null ? null : Number(nonWhite.toFixed(5)),
    });
  }

  checkAborted();
  if (problems.length) failNow('problems while taking the shots');

  const result = {
    page: opt.page,
    url: pageUrl.replace(origin, ''),
    width: opt.width,
    height: opt.height,
    device_scale_factor: 1,
    chromium: chromiumVersion,
    load_ms: state.loadAt !== null ? Math.round(state.loadAt) : null,
    load_ms_note: 'performance.now() at the model-viewer load event, i.e. ms since navigation start',
    wall_ms: Date.now() - t0,
    page_settings: {
      attributes: state.original,
      tone_mapping: settle.toneMapping,
      exposure: settle.exposure,
      environment_image: settle.environmentImage,
      skybox_image: settle.skyboxImage,
      shadow_intensity: settle.shadowIntensity,
    },
    bounding_box: {
      center_m: [c.x, c.y, c.z],
      dimensions_m: [d.x, d.y, d.z],
    },
    conventions: CONVENTIONS,
    shots,
    requests,
    console_warnings: consoleWarnings,
    console_errors: consoleErrors,
    external_requests: external,
    aborted_but_served: abortedButServed,
  };
  fs.writeFileSync(path.join(opt.out, 'shots.json'), JSON.stringify(result, null, 2) + '\n');
  process.stdout.write(`viewer-shots: ${opt.page}: ${shots.length} shots in ${opt.out}, model loaded in ` +
      `${result.load_ms} ms, total ${Date.now() - t0} ms\n`);
}

let code = 0;
try {
  await main();
} catch (e) {
  process.stderr.write(`viewer-shots: ${e && e.message ? e.message : e}\n`);
  code = 1;
} finally {
  if (browser) await browser.close().catch(() => {});
  if (server) server.close();
  if (userDataDir) fs.rmSync(userDataDir, {recursive: true, force: true});
}
process.exit(code);
