// Finds the npm packages that web/package.json installs, for the scripts in tests/web.
//
// Order: $CAROUSEL_WEB_MODULES (a node_modules folder), then the repository's own
// web/node_modules beside this folder, then normal resolution from this file
// (which also honours NODE_PATH).
import fs from 'node:fs';
import path from 'node:path';
import {createRequire} from 'node:module';
import {fileURLToPath} from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));

function candidates() {
  const dirs = [];
  if (process.env.CAROUSEL_WEB_MODULES) dirs.push(path.resolve(process.env.CAROUSEL_WEB_MODULES));
  dirs.push(path.resolve(here, '..', '..', 'web', 'node_modules'));
  return dirs.filter((d, i) => dirs.indexOf(d) === i && fs.existsSync(d));
}

/** require() a CommonJS entry of an installed web package, e.g. 'gltf-validator'. */
export function requireWeb(name) {
  const tried = [];
  for (const dir of candidates()) {
    // A file inside node_modules resolves bare names from that node_modules.
    const req = createRequire(path.join(dir, '_carousel_resolver.cjs'));
    try {
      return req(req.resolve(name, {paths: [dir]}));
    } catch (e) {
      if (e.code !== 'MODULE_NOT_FOUND') throw e;
      tried.push(dir);
    }
  }
  try {
    return createRequire(import.meta.url)(name);
  } catch (e) {
    if (e.code !== 'MODULE_NOT_FOUND') throw e;
    const where = tried.length ? tried.join(', ') : '(no node_modules folder found)';
    throw new Error(`cannot find npm package '${name}' (looked in ${where}, NODE_PATH and ` +
        `normal resolution); run 'npm ci' in web/ or set CAROUSEL_WEB_MODULES`);
  }
}

/** Absolute path of a file inside an installed web package, e.g. ('@google/model-viewer', 'dist/model-viewer.min.js'). */
export function webPackageFile(pkg, rel) {
  const manifest = requireWebResolve(`${pkg}/package.json`);
  return path.join(path.dirname(manifest), rel);
}

function requireWebResolve(spec) {
  for (const dir of candidates()) {
    const p = path.join(dir, spec);
    if (fs.existsSync(p)) return p;
  }
  return createRequire(import.meta.url).resolve(spec);
}
