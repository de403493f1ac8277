// rangekit ui: the 3D views (three.js 0.170, shipped in the package): points added view by view as they are
// decoded (Scan), a session's mesh (Sessions, and Scan when done), registered clouds (Registration). Drag to
// orbit, wheel to zoom. Coordinates in millimetres; meshes are read from their PLY (metres) and scaled.
import * as THREE from "three";
import { OrbitControls } from "/static/vendor/three/OrbitControls.js";
import { PLYLoader } from "/static/vendor/three/PLYLoader.js";

function colour(k) { return new THREE.Color().setHSL((k * 0.382) % 1, 0.7, 0.6); }   // golden-ratio hues: neighbours differ

function makeViewer(canvas) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setClearColor(0x1d2327);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(40, canvas.width / canvas.height, 1, 5000);
  camera.up.set(0, -1, 0);
  camera.position.set(0, -150, -450);
  scene.add(camera, new THREE.AmbientLight(0xffffff, 0.45));
  const light = new THREE.DirectionalLight(0xffffff, 1.6); light.position.set(0.3, -0.5, -1); camera.add(light);
  const controls = new OrbitControls(camera, canvas);
  const views = new Map(), box = new THREE.Box3();
  let mesh = null;

  function frameBox(b) {
    const centre = b.getCenter(new THREE.Vector3()), size = b.getSize(new THREE.Vector3()).length();
    controls.target.copy(centre);
    camera.position.copy(centre).add(new THREE.Vector3(0, -0.4 * size, -1.6 * size));
  }
  const viewer = {
    points: 0, vertices: 0,
    get count() { return views.size; },
    has: (k) => views.has(k),
    addView(k, xyz) {
      if (views.has(k)) return;
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", new THREE.BufferAttribute(xyz, 3));
      geometry.computeBoundingBox();
      const points = new THREE.Points(geometry, new THREE.PointsMaterial({ size: 1.2, color: colour(k) }));
      points.visible = mesh === null;
      scene.add(points); views.set(k, points); box.union(geometry.boundingBox);
      if (views.size === 1 && mesh === null) frameBox(box);     // frame the first view; later ones keep the user's view
      viewer.points += xyz.length / 3;
    },
    clear() {
      for (const p of views.values()) scene.remove(p);
      views.clear(); box.makeEmpty(); viewer.points = 0;
      if (mesh) { scene.remove(mesh); mesh = null; viewer.vertices = 0; }
    },
    // The mesh of a PLY file at url (metres), shown instead of the points (fetched with the page's token).
    async showMesh(url) {
      const r = await api(url);
      if (!r.ok) return 0;
      const geometry = new PLYLoader().parse(await r.arrayBuffer());
      geometry.scale(1000, 1000, 1000);
      if (!geometry.attributes.normal) geometry.computeVertexNormals();
      geometry.computeBoundingBox();
      if (mesh) scene.remove(mesh);
      mesh = new THREE.Mesh(geometry, new THREE.MeshStandardMaterial({ color: 0xb8c4cc, roughness: 0.6, side: THREE.DoubleSide }));
      scene.add(mesh);
      for (const p of views.values()) p.visible = false;
      frameBox(geometry.boundingBox);
      viewer.vertices = geometry.attributes.position.count;
      return viewer.vertices;
    },
  };
  (function frame() {
    if (canvas.offsetParent !== null) { controls.update(); renderer.render(scene, camera); }   // drawn while shown
    requestAnimationFrame(frame);
  })();
  return viewer;
}

window.rangekitScan3d = makeViewer(document.getElementById("scan-canvas"));
window.rangekitSession3d = makeViewer(document.getElementById("session-canvas"));
window.rangekitRegister3d = makeViewer(document.getElementById("register-canvas"));
window.dispatchEvent(new Event("rangekit3d"));     // the classic scripts waiting for the viewers (scan.js)
