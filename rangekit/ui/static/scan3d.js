// rangekit ui: the Scan page's 3D view (three.js, shipped in the package): each decoded view's points added as
// they come, coloured by view; drag to orbit, wheel to zoom. window.rangekitScan3d.addView(k, Float32Array mm).
import * as THREE from "three";
import { OrbitControls } from "/static/vendor/three/OrbitControls.js";

const canvas = document.getElementById("scan-canvas");
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setClearColor(0x1d2327);
const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(40, canvas.width / canvas.height, 1, 5000);
camera.up.set(0, -1, 0);
camera.position.set(0, -150, -450);
const controls = new OrbitControls(camera, canvas);
const views = new Map();
const box = new THREE.Box3();

function colour(k) { return new THREE.Color().setHSL((k * 0.137) % 1, 0.7, 0.6); }

function addView(k, xyz) {
  if (views.has(k)) return;
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(xyz, 3));
  geometry.computeBoundingBox();
  const points = new THREE.Points(geometry, new THREE.PointsMaterial({ size: 1.2, color: colour(k) }));
  scene.add(points);
  views.set(k, points);
  box.union(geometry.boundingBox);
  if (views.size === 1) {         // frame the first view; later ones keep the user's view
    const centre = box.getCenter(new THREE.Vector3()), size = box.getSize(new THREE.Vector3()).length();
    controls.target.copy(centre);
    camera.position.copy(centre).add(new THREE.Vector3(0, -0.4 * size, -1.6 * size));
  }
  window.rangekitScan3d.points += xyz.length / 3;
}

function clear() { for (const p of views.values()) scene.remove(p); views.clear(); box.makeEmpty(); window.rangekitScan3d.points = 0; }

window.rangekitScan3d = { addView, clear, points: 0, has: (k) => views.has(k), get count() { return views.size; } };

function frame() {
  controls.update();
  renderer.render(scene, camera);
  requestAnimationFrame(frame);
}
frame();
