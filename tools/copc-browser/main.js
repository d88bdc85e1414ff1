// Draws the decoded COPC points (decode.mjs) with THREE.Points, framed exactly as `pbrlod render`
// frames the input (camera::orbit in include/pbr_lod/core/camera.hpp, through make_camera in
// examples/pbrlod/tool.cpp), each point drawn as pbrlod draws an unstructured cloud's point
// (src/raster/reference.cpp): radius 0.8 × the distance to its 8th nearest neighbour; with a
// normal, a disc in the point's tangent plane (each pixel's ray intersected with the plane, as
// perspective-accurate splatting does), shaded as pbrlod's rasteriser shades by default (Lambert,
// two-sided, one directional light towards (0.35, 0.8, 0.5), ambient 0.15, flat colour 200 grey
// without colours); without one (or with shade=0 in the query), an unlit screen-aligned square of
// that projected diameter. The background is transparent: pbrlod's PNG has alpha 0 where nothing
// is drawn, which is what `pbrlod compare` takes for "not covered".
import * as THREE from 'three';

const q = new URLSearchParams(location.search);
const nums = (s, sep, n, what) => {
  const v = (s || '').split(sep).map(Number);
  if (v.length !== n || v.some((x) => !Number.isFinite(x))) throw new Error(`${what}: '${s}'`);
  return v;
};

async function run() {
  const data = q.get('data') || '/data';
  const [az, el, dist] = nums(q.get('view') || '30,20,3', ',', 3, 'view');
  const [w, h] = nums(q.get('size') || '512x512', 'x', 2, 'size');
  const up = q.get('up') || 'y';
  const centreWorld = nums(q.get('centre'), ',', 3, 'centre');
  let radius = Number(q.get('radius'));
  if (!(radius > 0) || !Number.isFinite(radius)) radius = 1;  // as camera::orbit
  const fovy = Number(q.get('fov') || 40);
  const shade = q.get('shade') !== '0';
  const radiusFactor = Number(q.get('radius_factor') || 0.8);  // reference_radius_factor

  const meta = await (await fetch(`${data}/points.json`)).json();
  const bin = await (await fetch(`${data}/points.bin`)).arrayBuffer();
  const n = meta.points;
  const part = (name, Type, size) =>
    meta.layout[name] ? new Type(bin, meta.layout[name].offset, size * n) : null;

  const geom = new THREE.BufferGeometry();
  geom.setAttribute('position', new THREE.BufferAttribute(part('position', Float32Array, 3), 3));
  geom.setAttribute('spacing', new THREE.BufferAttribute(part('spacing', Float32Array, 1), 1));
  const normal = shade ? part('normal', Int16Array, 3) : null;
  if (normal) geom.setAttribute('normal', new THREE.BufferAttribute(normal, 3, true));
  const rgb = part('rgb', Uint8Array, 3);
  if (rgb) geom.setAttribute('rgb', new THREE.BufferAttribute(rgb, 3, true));

  // Positions are relative to the COPC cube centre; so is the camera (subtracted in double).
  const c = meta.cube_centre;
  const centre = new THREE.Vector3(centreWorld[0] - c[0], centreWorld[1] - c[1], centreWorld[2] - c[2]);
  // camera::orbit: the direction to the eye in a y-up frame, permuted (z, x, y) for z-up.
  const a = (az * Math.PI) / 180, e = (el * Math.PI) / 180;
  const dy = [Math.cos(e) * Math.sin(a), Math.sin(e), Math.cos(e) * Math.cos(a)];
  const dir = up === 'z' ? [dy[2], dy[0], dy[1]] : dy;
  const d = dist * radius;
  const camera = new THREE.PerspectiveCamera(fovy, w / h, Math.max(d - 1.5 * radius, d * 1e-4),
                                             d + 1.5 * radius);
  camera.up.set(0, up === 'z' ? 0 : 1, up === 'z' ? 1 : 0);
  camera.position.set(centre.x + d * dir[0], centre.y + d * dir[1], centre.z + d * dir[2]);
  camera.lookAt(centre);
  camera.updateMatrixWorld();
  camera.updateProjectionMatrix();

  const focal = (0.5 * h) / Math.tan((fovy * Math.PI) / 360);  // pixels, as view::focal_px
  const material = new THREE.ShaderMaterial({
    glslVersion: THREE.GLSL3,
    defines: { ...(normal ? { HAS_NORMAL: '' } : {}), ...(rgb ? { HAS_RGB: '' } : {}) },
    uniforms: {
      focal: { value: focal },
      viewport: { value: new THREE.Vector2(w, h) },
      proj: { value: camera.projectionMatrix },
      radiusFactor: { value: radiusFactor },
      // the light is a world direction: into view space for the shading there
      lightDir: { value: new THREE.Vector3(0.35, 0.8, 0.5).normalize().transformDirection(camera.matrixWorldInverse) },
      ambient: { value: 0.15 },
      flatColour: { value: new THREE.Vector3(200 / 255, 200 / 255, 200 / 255) },
    },
    vertexShader: `
      uniform float focal;
      uniform float radiusFactor;
      uniform vec3 lightDir;
      uniform float ambient;
      uniform vec3 flatColour;
      in float spacing;
      #ifdef HAS_RGB
      in vec3 rgb;
      #endif
      out vec3 vColour;
      out vec3 vCentre;  // view space
      out vec3 vNormal;  // view space, zero: a screen-aligned square
      out float vRadius;
      void main() {
        vec4 mv = modelViewMatrix * vec4(position, 1.0);
        gl_Position = projectionMatrix * mv;
        float r = radiusFactor * spacing;
        float z = -mv.z;
        #ifdef HAS_RGB
        vec3 albedo = rgb;
        #else
        vec3 albedo = flatColour;
        #endif
        vec3 n = vec3(0.0);
        #ifdef HAS_NORMAL
        if (dot(normal, normal) > 0.25) n = normalize(normalMatrix * normal);
        #endif
        float lit = 1.0;
        if (n != vec3(0.0)) {
          if (dot(n, mv.xyz) > 0.0) n = -n;  // two-sided: the side the eye sees
          lit = clamp(ambient + (1.0 - ambient) * max(0.0, dot(n, lightDir)), 0.0, 1.0);
          // A sprite that holds the disc's projection (its bounding sphere's, widened off axis).
          float off = 1.0 + dot(mv.xy, mv.xy) / (z * z);
          gl_PointSize = 2.0 * r * focal / max(z - r, 1e-3 * z) * off + 2.0;
        } else {
          gl_PointSize = max(1.0, 2.0 * r * focal / z);  // the projected diameter, as pbrlod
        }
        vColour = albedo * lit;
        vCentre = mv.xyz;
        vNormal = n;
        vRadius = r;
      }`,
    fragmentShader: `
      uniform float focal;
      uniform vec2 viewport;
      uniform mat4 proj;
      in vec3 vColour;
      in vec3 vCentre;
      in vec3 vNormal;
      in float vRadius;
      out highp vec4 fragColour;
      void main() {
        if (vNormal != vec3(0.0)) {
          // The pixel's ray from the eye (view space, looking down -z) meets the splat's plane.
          vec3 ray = vec3((gl_FragCoord.xy - 0.5 * viewport) / focal, -1.0);
          float den = dot(ray, vNormal);
          if (abs(den) < 1e-8) discard;
          float t = dot(vCentre, vNormal) / den;
          vec3 p = t * ray;
          if (t <= 0.0 || dot(p - vCentre, p - vCentre) > vRadius * vRadius) discard;
          vec4 clip = proj * vec4(p, 1.0);
          gl_FragDepth = clamp(0.5 * clip.z / clip.w + 0.5, 0.0, 1.0);
        } else {
          gl_FragDepth = gl_FragCoord.z;
        }
        fragColour = vec4(vColour, 1.0);
      }`,
  });

  const canvas = document.getElementById('view');
  const renderer = new THREE.WebGLRenderer({
    canvas, antialias: false, alpha: true, premultipliedAlpha: false, preserveDrawingBuffer: true,
  });
  renderer.setPixelRatio(1);
  renderer.setSize(w, h);
  renderer.outputColorSpace = THREE.LinearSRGBColorSpace;  // bytes as pbrlod writes them
  renderer.setClearColor(0x000000, 0);
  const scene = new THREE.Scene();
  scene.add(new THREE.Points(geom, material));
  const t0 = performance.now();
  renderer.render(scene, camera);
  const gl = renderer.getContext();
  gl.finish();
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  return {
    ok: true,
    points: n,
    copc_level: meta.copc_level,
    splats: normal ? 'oriented discs, shaded' : 'screen squares, unlit',
    radius_factor: radiusFactor,
    width: w,
    height: h,
    render_ms: performance.now() - t0,
    point_size_range: Array.from(gl.getParameter(gl.ALIASED_POINT_SIZE_RANGE)),
    webgl: dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER),
    three: THREE.REVISION,
  };
}

run().then(
  (r) => { window.copcDone = r; },
  (err) => { window.copcDone = { ok: false, error: String(err && err.stack || err) }; },
);
