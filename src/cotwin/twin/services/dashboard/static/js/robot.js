// The robot in 3D (three.js, vendored): links and geometry from the p-model's kinematic tree as the
// server describes it (describe.py), posed from the observed joint angles exactly as
// KinematicTree.forward does: child = parent · before · motion(axis, q) · after. With two sides the
// first (the PT) is drawn as a translucent ghost around the second (the DT). Renders on demand only:
// a new pose or a camera move, at most `fps` times a second.

import * as THREE from "../vendor/three.min.js";

const SIDE_LOOK = [
  { color: 0xd9480f, opacity: 0.35 }, // PT ghost (when there are two sides)
  { color: 0x9aa6b5, opacity: 1.0 },
];

function matrix(rowMajor) {
  return new THREE.Matrix4().set(...rowMajor);
}

function geometry(g) {
  const s = g.size;
  switch (g.kind) {
    case "box": return new THREE.BoxGeometry(s.length, s.width, s.height);
    case "cylinder": return new THREE.CylinderGeometry(s.radius, s.radius, s.length, 28).rotateX(Math.PI / 2);
    case "capsule": return new THREE.CapsuleGeometry(s.radius, s.length, 6, 16).rotateX(Math.PI / 2);
    case "sphere": return new THREE.SphereGeometry(s.radius, 24, 16);
    default: return null;
  }
}

function fixed(m) {
  const g = new THREE.Group();
  g.matrixAutoUpdate = false;
  g.matrix.copy(m);
  return g;
}

class RobotModel {
  constructor(robot, look) {
    const material = new THREE.MeshStandardMaterial({ color: look.color, metalness: 0.25, roughness: 0.55,
      transparent: look.opacity < 1, opacity: look.opacity, depthWrite: look.opacity >= 1 });
    const links = {};
    for (const link of robot.links) {
      const group = new THREE.Group();
      for (const g of link.geoms) {
        const geo = geometry(g);
        if (!geo) continue;
        const mesh = new THREE.Mesh(geo, material);
        mesh.matrixAutoUpdate = false;
        mesh.matrix.copy(matrix(g.pose));
        group.add(mesh);
      }
      links[link.name] = group;
    }
    this.links = links;
    this.label = robot.label || robot.name;
    this.root = fixed(matrix(robot.root_pose));
    this.root.add(links[robot.root]);
    this.motions = [];
    for (const j of robot.joints) {
      const before = fixed(matrix(j.before));
      const motion = new THREE.Group();
      const after = fixed(matrix(j.after));
      links[j.parent].add(before);
      before.add(motion);
      motion.add(after);
      after.add(links[j.child]);
      if (j.kind !== "fixed") this.motions.push({ joint: j, group: motion, axis: new THREE.Vector3(...j.axis) });
    }
  }

  // values: variable name -> joint position; true if anything moved visibly
  pose(values) {
    let moved = false;
    for (const m of this.motions) {
      const q = values[m.joint.variable];
      if (q === undefined || q === null || Number.isNaN(q)) continue;
      if (m.q !== undefined && Math.abs(q - m.q) < 1e-6) continue;
      m.q = q;
      moved = true;
      if (m.joint.kind === "revolute") m.group.quaternion.setFromAxisAngle(m.axis, q);
      else m.group.position.copy(m.axis).multiplyScalar(q);
    }
    return moved;
  }
}

function plate(scene) {
  const p = scene.plate;
  const w = p.x1 - p.x0, h = p.y1 - p.y0;
  const canvas = document.createElement("canvas");
  const res = 1200; // pixels per metre of plate
  canvas.width = Math.round(w * res); canvas.height = Math.round(h * res);
  const g = canvas.getContext("2d");
  g.fillStyle = "#c5c9d0"; g.fillRect(0, 0, canvas.width, canvas.height);
  g.fillStyle = "#3b3f46";
  for (const [x, y] of scene.holes) { // texture u along +x, v along +y (canvas rows run the other way)
    g.beginPath();
    g.arc((x - p.x0) * res, canvas.height - (y - p.y0) * res, scene.hole_radius * res, 0, 2 * Math.PI);
    g.fill();
  }
  const top = new THREE.MeshStandardMaterial({ map: new THREE.CanvasTexture(canvas), roughness: 0.8 });
  top.map.colorSpace = THREE.SRGBColorSpace;
  const sides = new THREE.MeshStandardMaterial({ color: 0xaeb3bb, roughness: 0.8 });
  const mesh = new THREE.Mesh(new THREE.BoxGeometry(w, h, p.thickness), [sides, sides, sides, sides, top, sides]);
  mesh.position.set((p.x0 + p.x1) / 2, (p.y0 + p.y1) / 2, -p.thickness / 2);
  return mesh;
}

export class RobotView {
  constructor(container, model, { fps = 12 } = {}) {
    this.container = container;
    this.variables = model.variables.map((v) => v.name);
    this.sides = model.sides;
    this.minInterval = 1000 / fps;
    this.frames = 0;
    try {
      // no multisampling: on a machine without a GPU (software GL) it would cost the twin's CPU
      this.renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
    } catch (err) {
      const note = document.createElement("div");
      note.className = "note";
      note.textContent = "the 3D view needs WebGL, which this browser does not offer";
      container.append(note);
      this.renderer = null;
      return;
    }
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    container.append(this.renderer.domElement);
    const scene = (this.scene = new THREE.Scene());
    scene.background = new THREE.Color(0xe9edf2);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.8);
    sun.position.set(1.5, -1.0, 3.0);
    scene.add(sun);
    const grid = new THREE.GridHelper(4, 40, 0xb8bec8, 0xd3d8df);
    grid.rotation.x = Math.PI / 2;
    grid.position.z = model.scene ? -model.scene.plate.thickness - 0.001 : -0.001;
    scene.add(grid);
    let target = new THREE.Vector3(0, 0, 0.3);
    if (model.scene) {
      scene.add(plate(model.scene));
      const p = model.scene.plate;
      target = new THREE.Vector3((p.x0 + p.x1) / 3, (p.y0 + p.y1) / 3, 0.2);
    }
    this.robots = {}; // side -> its robots (a cell of several robots: model.robots, each at its base pose)
    const drawings = model.robots || [model.robot];
    this.sides.forEach((side, i) => {
      const look = this.sides.length > 1 ? SIDE_LOOK[i] : SIDE_LOOK[1];
      this.robots[side] = drawings.map((drawing) => {
        const robot = new RobotModel(drawing, look);
        scene.add(robot.root);
        return robot;
      });
    });
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 50);
    this.camera.up.set(0, 0, 1);
    this.target = target;
    this.orbit = new THREE.Spherical(1.9, 1.0, -2.0); // distance, angle from +z, azimuth from +x
    this._place();
    this._controls();
    new ResizeObserver(() => this._resize()).observe(container);
    this._resize();
  }

  _place() {
    const o = this.orbit;
    const r = o.radius, phi = o.phi, theta = o.theta;
    this.camera.position.set(this.target.x + r * Math.sin(phi) * Math.cos(theta),
      this.target.y + r * Math.sin(phi) * Math.sin(theta), this.target.z + r * Math.cos(phi));
    this.camera.lookAt(this.target);
    this.invalidate();
  }

  _controls() {
    const el = this.renderer.domElement;
    let drag = null;
    el.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY }; el.setPointerCapture(e.pointerId); });
    el.addEventListener("pointerup", () => { drag = null; });
    el.addEventListener("pointermove", (e) => {
      if (!drag) return;
      this.orbit.theta -= (e.clientX - drag.x) * 0.008;
      this.orbit.phi = Math.min(Math.PI - 0.05, Math.max(0.05, this.orbit.phi - (e.clientY - drag.y) * 0.008));
      drag = { x: e.clientX, y: e.clientY };
      this._place();
    });
    el.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.orbit.radius = Math.min(12, Math.max(0.3, this.orbit.radius * Math.exp(e.deltaY * 0.001)));
      this._place();
    }, { passive: false });
  }

  _resize() {
    if (!this.renderer) return;
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, true);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.invalidate();
  }

  // row: the wire sample's per-side [values, states] list
  pose(row) {
    if (!this.renderer) return;
    let moved = false;
    this.sides.forEach((side, i) => {
      const values = row[2 * i];
      if (!values) return;
      const named = {};
      this.variables.forEach((name, k) => { named[name] = values[k]; });
      for (const robot of this.robots[side]) moved = robot.pose(named) || moved;
    });
    if (moved) this.invalidate();
  }

  // world pose of every link of a side (row-major 4x4), as drawn: for checking against the p-model
  // (several robots: keyed ROBOT/link)
  linkPoses(side) {
    const robots = this.robots[side];
    const out = {};
    for (const robot of robots) {
      robot.root.updateMatrixWorld(true);
      for (const [name, group] of Object.entries(robot.links)) {
        const m = group.matrixWorld.elements; // column-major
        out[robots.length > 1 ? `${robot.label}/${name}` : name] = [0, 1, 2, 3].flatMap((r) => [0, 1, 2, 3].map((c) => m[c * 4 + r]));
      }
    }
    return out;
  }

  invalidate() {
    if (!this.renderer || this._scheduled) return;
    this._scheduled = true;
    const wait = Math.max(0, this.minInterval - (performance.now() - (this.last || 0)));
    setTimeout(() => requestAnimationFrame(() => {
      this._scheduled = false;
      this.last = performance.now();
      this.renderer.render(this.scene, this.camera);
      if (!this.frames) this.firstFrameAt = performance.now();
      this.frames++;
    }), wait);
  }
}
