// @ts-check
// The viewer page's script: opens `?pack=URL` with the Rust viewer (vortex_web.js, made by
// wasm-bindgen), runs the frame loop, feeds it the input, shows the counters, and exposes
// `window.vortex` (frames, converged, counters, release) to tests and to the console.
import init, { Viewer } from "./vortex_web.js";

const params = new URLSearchParams(location.search);
const canvas = /** @type {HTMLCanvasElement} */ (document.getElementById("view"));
const counters = /** @type {HTMLElement} */ (document.getElementById("counters"));
const state = {
  frames: 0,
  converged: false,
  error: "",
  counters: {},
  view: {},
  release: () => {},
  measureDecode: async (/** @type {number} */ _rounds) => {},
  /** @type {{ wasm: number, bitmap: number } | null} */
  decode: null,
  /** Milliseconds from the page's start to its first frame drawn. */
  firstPictureMs: 0,
  /** Each frame's CPU time (ms), the last 10,000 frames: for measurements. */
  cpuMs: /** @type {number[]} */ ([]),
};
// @ts-ignore: the page's handle for tests and the console.
window.vortex = state;

function fail(/** @type {unknown} */ e) {
  state.error = String(e instanceof Error ? e.message : e);
  /** @type {HTMLElement} */ (document.getElementById("error")).textContent = state.error;
}

async function main() {
  const pack = params.get("pack");
  if (!pack) throw new Error("no pack: open index.html?pack=URL");
  if (!("gpu" in navigator)) throw new Error("this browser has no WebGPU (navigator.gpu)");
  // The canvas in device pixels: its CSS size times the pixel ratio, or `size` exactly.
  const size = params.get("size")?.match(/^(\d+)x(\d+)$/);
  if (size) {
    canvas.classList.add("fixed");
    canvas.width = Number(size[1]);
    canvas.height = Number(size[2]);
    canvas.style.width = `${canvas.width / devicePixelRatio}px`;
    canvas.style.height = `${canvas.height / devicePixelRatio}px`;
  } else {
    canvas.width = Math.round(canvas.clientWidth * devicePixelRatio);
    canvas.height = Math.round(canvas.clientHeight * devicePixelRatio);
  }
  await init();
  const viewer = await Viewer.open(canvas, new URL(pack, location.href).href, params.has("hold"));
  state.release = () => viewer.release();
  // The decoders measured on the root tile (docs/benchmarks.md): the runtime's, in wasm, and the
  // browser's (createImageBitmap, then the texels read back through a canvas, as a loader would
  // need them). Sets `state.decode` to milliseconds per tile.
  state.measureDecode = async (/** @type {number} */ rounds) => {
    const wasm = viewer.decode_ms(rounds);
    const blob = new Blob([viewer.root_payload()], { type: "image/jpeg" });
    const started = performance.now();
    for (let i = 0; i < rounds; i++) {
      const bitmap = await createImageBitmap(blob, { premultiplyAlpha: "none", colorSpaceConversion: "none" });
      const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
      const context = /** @type {OffscreenCanvasRenderingContext2D} */ (canvas.getContext("2d"));
      context.drawImage(bitmap, 0, 0);
      context.getImageData(0, 0, bitmap.width, bitmap.height);
      bitmap.close();
    }
    state.decode = { wasm, bitmap: (performance.now() - started) / rounds };
  };
  controls(viewer);
  if (!size) {
    // The canvas follows the window, in device pixels.
    new ResizeObserver(() => {
      canvas.width = Math.max(1, Math.round(canvas.clientWidth * devicePixelRatio));
      canvas.height = Math.max(1, Math.round(canvas.clientHeight * devicePixelRatio));
      viewer.resize(canvas.width, canvas.height);
    }).observe(canvas);
  }
  let shown = 0;
  const frame = (/** @type {number} */ now) => {
    try {
      viewer.frame();
    } catch (e) {
      fail(e);
      return;
    }
    state.frames += 1;
    if (state.frames === 1) state.firstPictureMs = performance.now();
    state.converged = viewer.converged();
    // The counters are drawn four times a second; the state keeps the last frame's.
    state.counters = JSON.parse(viewer.counters());
    state.view = JSON.parse(viewer.view());
    state.cpuMs.push(/** @type {any} */ (state.counters).last.cpu_ms);
    if (state.cpuMs.length > 10000) state.cpuMs.shift();
    if (now - shown > 250) {
      shown = now;
      const c = /** @type {any} */ (state.counters);
      counters.textContent =
        `frame ${c.frames}${c.converged ? " (converged)" : ""}\n` +
        `resident ${c.resident}  in flight ${c.in_flight}\n` +
        `fallback ${(100 * c.last.fallback_fraction).toFixed(1)}%  cpu ${c.last.cpu_ms.toFixed(2)} ms\n` +
        `fetched ${(c.bytes_fetched / 1024).toFixed(0)} KiB in ${c.requests} requests\n` +
        `${c.filter}, anisotropy ${c.anisotropy}${c.load_errors ? `, ${c.load_errors} errors` : ""}` +
        c.gpu_errors.map((/** @type {string} */ e) => `\nGPU: ${e}`).join("");
    }
    requestAnimationFrame(frame);
  };
  requestAnimationFrame(frame);
}

/** Drag to pan, wheel to zoom at the pointer, the panel's switches. */
function controls(/** @type {Viewer} */ viewer) {
  let dragging = false;
  canvas.addEventListener("pointerdown", (e) => {
    dragging = true;
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointerup", () => (dragging = false));
  canvas.addEventListener("pointermove", (e) => {
    if (dragging) viewer.pan(e.movementX * devicePixelRatio, e.movementY * devicePixelRatio);
  });
  canvas.addEventListener(
    "wheel",
    (e) => {
      e.preventDefault();
      const r = canvas.getBoundingClientRect();
      const x = ((e.clientX - r.left) * canvas.width) / r.width;
      const y = ((e.clientY - r.top) * canvas.height) / r.height;
      viewer.zoom(Math.pow(1.0015, -e.deltaY), x, y);
    },
    { passive: false },
  );
  const select = (/** @type {string} */ id) => /** @type {HTMLSelectElement} */ (document.getElementById(id));
  select("filter").value = viewer.filter();
  select("filter").addEventListener("change", (e) => {
    try {
      viewer.set_filter(select("filter").value);
    } catch (err) {
      fail(err);
    }
  });
  select("anisotropy").addEventListener("change", () => viewer.set_anisotropy(Number(select("anisotropy").value)));
  const residency = /** @type {HTMLInputElement} */ (document.getElementById("residency"));
  residency.addEventListener("change", () => viewer.set_residency_view(residency.checked));
  /** @type {HTMLElement} */ (document.getElementById("home")).addEventListener("click", () => viewer.home());
}

main().catch(fail);
