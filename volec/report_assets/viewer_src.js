// volec's report viewer: the food mesh and clouds of one estimate, in three.js.
// This is the source; viewer.min.js is it bundled with three.js by scripts/vendor_viewer.sh
// (three.js is MIT-licensed, see LICENSE-three.txt). volec's report.html inlines the bundle
// and its data, so the page needs no network at all.
//
// window.VolecViewer.start(container, data) draws `data` (made by volec/report.py):
//   up: [x, y, z]                 the world's up direction (the support plane's normal)
//   mesh: {positions, indices}    base64 float32 xyz (metres) and uint32 triangle indices
//   layers: [{name, label, kind: "points", positions, colors?, color?, size_m, visible}]
// and sets window.volecViewerState = {ready, frames, error} for tests and the page.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

function decode(base64, ArrayType) {
  const text = atob(base64);
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  return new ArrayType(bytes.buffer);
}

function meshObject(mesh) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(decode(mesh.positions, Float32Array), 3));
  geometry.setIndex(new THREE.BufferAttribute(decode(mesh.indices, Uint32Array), 1));
  geometry.computeVertexNormals();
  const material = new THREE.MeshStandardMaterial({
    color: 0xd8b27a, roughness: 0.75, metalness: 0.0, side: THREE.DoubleSide,
    transparent: true, opacity: 1.0,
  });
  return new THREE.Mesh(geometry, material);
}

function pointsObject(layer) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(decode(layer.positions, Float32Array), 3));
  const options = { size: layer.size_m, sizeAttenuation: true };
  if (layer.colors) {
    const rgb = decode(layer.colors, Uint8Array);
    geometry.setAttribute('color', new THREE.BufferAttribute(rgb, 3, true));
    options.vertexColors = true;
  } else {
    options.color = new THREE.Color(layer.color);
  }
  return new THREE.Points(geometry, new THREE.PointsMaterial(options));
}

function frameCamera(camera, controls, objects, up) {
  const box = new THREE.Box3();
  objects.forEach((o) => box.expandByObject(o));
  const sphere = box.getBoundingSphere(new THREE.Sphere());
  const radius = Math.max(sphere.radius, 1e-3);
  // look from 30 degrees above the horizon, so the item fills most of the view
  const side = new THREE.Vector3(1, 0, 0);
  if (Math.abs(side.dot(up)) > 0.9) side.set(0, 0, 1);
  side.addScaledVector(up, -side.dot(up)).normalize();
  const direction = side.multiplyScalar(Math.cos(Math.PI / 6)).addScaledVector(up, Math.sin(Math.PI / 6));
  const distance = radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 0.9;
  camera.up.copy(up);
  camera.position.copy(sphere.center).addScaledVector(direction, distance);
  camera.near = distance / 100;
  camera.far = distance * 100;
  camera.updateProjectionMatrix();
  controls.target.copy(sphere.center);
  controls.update();
}

function start(container, data) {
  const state = { ready: false, frames: 0, error: null };
  window.volecViewerState = state;
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(container.clientWidth, container.clientHeight);
  renderer.setClearColor(0xf4f4f2);
  container.appendChild(renderer.domElement);

  const up = new THREE.Vector3().fromArray(data.up).normalize();
  const scene = new THREE.Scene();
  const sky = new THREE.HemisphereLight(0xffffff, 0x8a8070, 1.6);
  sky.position.copy(up);
  scene.add(sky);
  const sun = new THREE.DirectionalLight(0xffffff, 1.4);
  scene.add(sun);

  const objects = {};
  if (data.mesh) objects.mesh = meshObject(data.mesh);
  for (const layer of data.layers) objects[layer.name] = pointsObject(layer);
  Object.entries(objects).forEach(([name, object]) => {
    const layer = data.layers.find((l) => l.name === name);
    object.visible = layer ? layer.visible : true;
    scene.add(object);
  });

  const camera = new THREE.PerspectiveCamera(35, container.clientWidth / container.clientHeight);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.enableDamping = true;
  controls.autoRotate = true;
  controls.autoRotateSpeed = 1.5;
  frameCamera(camera, controls, Object.values(objects), up);

  // the page's checkboxes: data-layer="NAME" shows or hides a layer, id="volec-rotate" spins
  container.ownerDocument.querySelectorAll('input[data-layer]').forEach((box) => {
    const object = objects[box.dataset.layer];
    if (!object) { box.disabled = true; return; }
    box.checked = object.visible;
    box.addEventListener('change', () => { object.visible = box.checked; });
  });
  const rotate = container.ownerDocument.getElementById('volec-rotate');
  if (rotate) rotate.addEventListener('change', () => { controls.autoRotate = rotate.checked; });
  const seeThrough = container.ownerDocument.getElementById('volec-see-through');
  if (seeThrough && objects.mesh) {
    seeThrough.addEventListener('change', () => {
      objects.mesh.material.opacity = seeThrough.checked ? 0.35 : 1.0;
      objects.mesh.material.depthWrite = !seeThrough.checked;
    });
  }

  window.addEventListener('resize', () => {
    camera.aspect = container.clientWidth / container.clientHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(container.clientWidth, container.clientHeight);
  });
  renderer.setAnimationLoop(() => {
    controls.update();
    sun.position.copy(camera.position).sub(controls.target).addScaledVector(up, 0.5 * camera.position.distanceTo(controls.target));
    renderer.render(scene, camera);
    state.frames += 1;
    state.ready = true;
  });
  return state;
}

function startSafely(container, data) {
  try {
    return start(container, data);
  } catch (error) {
    window.volecViewerState = { ready: false, frames: 0, error: String(error) };
    container.textContent = '3D view unavailable here (' + error + '); the pictures below show the same.';
    return window.volecViewerState;
  }
}

window.VolecViewer = { start: startSafely };
