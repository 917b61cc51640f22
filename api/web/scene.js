// 3D views (three.js, vendored): an object with its contacts, a hand's links, a replay.
// Z is up, as in the sessions. Drag to turn the view, wheel to zoom.
import * as THREE from './vendor/three/three.module.js';

/** A three.js view in a canvas appended to `el`, drawn on demand or every frame. */
export class View {
  constructor(el, radius = 0.2) {
    this.canvas = document.createElement('canvas');
    this.canvas.className = 'view3d';
    el.appendChild(this.canvas);
    // No antialiasing, at most 1.5 device pixels a pixel: software GL (a headless browser, a
    // machine without a GPU) keeps up with the animation.
    this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: false });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 1.5));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xeef1f5);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.001, 100);
    this.camera.up.set(0, 0, 1);
    this.target = new THREE.Vector3(0, 0, 0);
    this.orbit = { az: -0.9, el: 0.5, r: radius * 4 };
    this.scene.add(new THREE.AmbientLight(0xffffff, 1.2));
    const sun = new THREE.DirectionalLight(0xffffff, 2.0);
    sun.position.set(1, -1, 2);
    this.scene.add(sun);
    this.controls();
    this.resize();
    this.placeCamera();
    new ResizeObserver(() => { this.resize(); this.render(); }).observe(this.canvas);
  }

  controls() {
    let drag = null;
    this.canvas.addEventListener('pointerdown', e => { drag = [e.clientX, e.clientY]; this.canvas.setPointerCapture(e.pointerId); });
    this.canvas.addEventListener('pointerup', () => { drag = null; });
    this.canvas.addEventListener('pointermove', e => {
      if (!drag) return;
      this.orbit.az -= (e.clientX - drag[0]) * 0.01;
      this.orbit.el = Math.max(-1.5, Math.min(1.5, this.orbit.el + (e.clientY - drag[1]) * 0.01));
      drag = [e.clientX, e.clientY];
      this.placeCamera();
      this.render();
    });
    this.canvas.addEventListener('wheel', e => {
      e.preventDefault();
      this.orbit.r *= Math.exp(e.deltaY * 0.001);
      this.placeCamera();
      this.render();
    }, { passive: false });
  }

  placeCamera() {
    const { az, el, r } = this.orbit;
    this.camera.position.set(
      this.target.x + r * Math.cos(el) * Math.cos(az),
      this.target.y + r * Math.cos(el) * Math.sin(az),
      this.target.z + r * Math.sin(el));
    this.camera.lookAt(this.target);
  }

  /** Aims at `object`'s bounding sphere and backs off until all of it is in view. */
  frame(object, margin = 1.1) {
    const box = new THREE.Box3().setFromObject(object);
    if (box.isEmpty()) return;
    const sphere = box.getBoundingSphere(new THREE.Sphere());
    this.target.copy(sphere.center);
    const halfFov = THREE.MathUtils.degToRad(this.camera.fov) / 2;
    const half = Math.min(halfFov, Math.atan(Math.tan(halfFov) * this.camera.aspect));
    this.orbit.r = Math.max(0.05, (margin * sphere.radius) / Math.sin(half));
    this.placeCamera();
  }

  resize() {
    const w = this.canvas.clientWidth || 400;
    const hgt = this.canvas.clientHeight || 300;
    this.renderer.setSize(w, hgt, false);
    this.camera.aspect = w / hgt;
    this.camera.updateProjectionMatrix();
  }

  render() {
    this.renderer.render(this.scene, this.camera);
  }

  dispose() {
    this.renderer.dispose();
  }
}

const OBJECT_MATERIAL = () => new THREE.MeshStandardMaterial({ color: 0x5b8fd6, transparent: true, opacity: 0.55 });

/** A mesh of an object: `shape` sphere/box/cylinder, `size` as a skill's parameters give it. */
export function objectMesh(shape, size) {
  let geometry;
  if (shape === 'sphere') geometry = new THREE.SphereGeometry(size[0], 32, 16);
  else if (shape === 'box') geometry = new THREE.BoxGeometry(2 * size[0], 2 * size[1], 2 * size[2]);
  else if (shape === 'cylinder') {
    geometry = new THREE.CylinderGeometry(size[0], size[0], 2 * size[1], 32);
    geometry.rotateX(Math.PI / 2); // three's cylinders stand on y; ours on z
  } else geometry = new THREE.SphereGeometry(0.03, 16, 8);
  return new THREE.Mesh(geometry, OBJECT_MATERIAL());
}

/** A primitive of a hand link: {kind, size, pose: [x, y, z, qx, qy, qz, qw]} in the link. */
export function primitiveMesh(p, colour) {
  let geometry;
  if (p.kind === 'sphere') geometry = new THREE.SphereGeometry(p.size[0], 16, 8);
  else if (p.kind === 'box') geometry = new THREE.BoxGeometry(p.size[0], p.size[1], p.size[2]);
  else {
    geometry = new THREE.CylinderGeometry(p.size[0], p.size[0], p.size[1], 16);
    geometry.rotateX(Math.PI / 2);
  }
  const m = new THREE.Mesh(geometry, new THREE.MeshStandardMaterial({ color: colour }));
  setPose(m, p.pose);
  return m;
}

/** Sets an Object3D's pose from [x, y, z, qx, qy, qz, qw]. */
export function setPose(o, pose) {
  o.position.set(pose[0], pose[1], pose[2]);
  o.quaternion.set(pose[3], pose[4], pose[5], pose[6]);
}

/** A contact: a dot at `point` and an arrow along `normal` (into the object) ending there. */
export function contactMarker(point, normal, colour = 0xd62728, length = 0.04) {
  const g = new THREE.Group();
  const dot = new THREE.Mesh(new THREE.SphereGeometry(0.004, 12, 8), new THREE.MeshStandardMaterial({ color: colour }));
  dot.position.set(...point);
  g.add(dot);
  const n = new THREE.Vector3(...normal).normalize();
  const origin = new THREE.Vector3(...point).addScaledVector(n, -length);
  g.add(new THREE.ArrowHelper(n, origin, length, colour, length * 0.3, length * 0.15));
  return g;
}

/** A force arrow (updated each frame): call set(point, vector_N). */
export class ForceArrow {
  constructor(colour = 0xd62728, scale = 0.02) {
    this.scale = scale;
    this.arrow = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 0.01, colour);
  }

  set(point, force) {
    const f = new THREE.Vector3(...force);
    const len = f.length() * this.scale;
    this.arrow.visible = len > 1e-4;
    if (!this.arrow.visible) return;
    this.arrow.position.set(...point);
    this.arrow.setDirection(f.normalize());
    this.arrow.setLength(len, Math.min(0.3 * len, 0.015), Math.min(0.15 * len, 0.008));
  }
}

export { THREE };
