// The 3D view: the scene's entities (foxglove.SceneUpdate: links, bodies, nozzle, paths, the printed
// mesh) in their frames, moved by foxglove.FrameTransforms, and the particles (foxglove.PointCloud)
// as shaded sphere sprites coloured by a chosen field, on three.js.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

/** Colour maps, the same in the shader and on the colour bar: a viridis-like ramp, and categories. */
export const RAMP = [[0.267, 0.005, 0.329], [0.229, 0.322, 0.546], [0.128, 0.567, 0.551], [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]];
export const CATEGORIES = [[0.80, 0.55, 0.35], [0.35, 0.65, 0.45], [0.75, 0.35, 0.45], [0.55, 0.45, 0.75], [0.80, 0.75, 0.35], [0.35, 0.65, 0.75]];
export function rampColor(t) {
  const x = Math.min(Math.max(t, 0), 1) * (RAMP.length - 1);
  const i = Math.min(Math.floor(x), RAMP.length - 2), f = x - i;
  return RAMP[i].map((c, k) => c + (RAMP[i + 1][k] - c) * f);
}

const PARTICLE_VERTEX = `
  attribute float value;
  uniform float radius;      // m
  uniform float pixelScale;  // pixels per unit of (size / depth)
  varying float vValue;
  void main() {
    vec4 view = modelViewMatrix * vec4(position, 1.0);
    gl_Position = projectionMatrix * view;
    gl_PointSize = max(2.0, 2.0 * radius * pixelScale / -view.z);
    vValue = value;
  }`;
const PARTICLE_FRAGMENT = `
  uniform float low, high;
  uniform bool categories;
  uniform vec3 ramp[${RAMP.length}];
  uniform vec3 palette[${CATEGORIES.length}];
  varying float vValue;
  void main() {
    vec2 p = gl_PointCoord * 2.0 - 1.0;
    float r2 = dot(p, p);
    if (r2 > 1.0) discard;
    vec3 color;
    if (categories) {
      color = palette[int(mod(vValue + 0.5, ${CATEGORIES.length}.0))];
    } else {
      float t = clamp((vValue - low) / max(high - low, 1e-12), 0.0, 1.0) * ${RAMP.length - 1}.0;
      int i = int(min(floor(t), ${RAMP.length - 2}.0));
      color = mix(ramp[i], ramp[i + 1], t - float(i));
    }
    // A sphere's normal at this point of the sprite, lit from above and the viewer.
    vec3 normal = vec3(p.x, -p.y, sqrt(1.0 - r2));
    float light = 0.35 + 0.65 * max(0.0, dot(normal, normalize(vec3(0.3, 0.6, 0.75))));
    gl_FragColor = vec4(color * light, 1.0);
  }`;

export class World {
  constructor(canvas) {
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0.82, 0.86, 0.92);
    // REP 103: z up.
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 100);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera, canvas);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.4);
    sun.position.set(0.35, 0.25, 1);
    this.scene.add(sun);
    const grid = new THREE.GridHelper(4, 40, 0x888888, 0xbbbbbb);
    grid.rotation.x = Math.PI / 2;
    this.scene.add(grid);
    this.frames = new Map([["world", this.scene]]);  // frame id → Object3D
    this.entities = new Map();                         // entity id → Object3D
    this.showMesh = true;
    this.showDeviation = false;
    this.particles = null;
    this.resetView();
  }

  resetView() {
    this.camera.position.set(1.9, -1.4, 1.1);
    this.controls.target.set(0.55, 0, 0.25);
    this.controls.update();
  }

  frame(id) {
    if (!this.frames.has(id)) {
      const object = new THREE.Group();
      object.name = id;
      this.scene.add(object);
      this.frames.set(id, object);
    }
    return this.frames.get(id);
  }

  /** foxglove.FrameTransforms: each child frame placed in its parent. */
  applyTransforms(message) {
    for (const transform of message.transforms) {
      const child = this.frame(transform.child_frame_id);
      const parent = this.frame(transform.parent_frame_id || "world");
      if (child.parent !== parent) parent.add(child);
      const t = transform.translation || {}, q = transform.rotation || {};
      child.position.set(t.x || 0, t.y || 0, t.z || 0);
      child.quaternion.set(q.x || 0, q.y || 0, q.z || 0, q.w ?? 1);
    }
  }

  /** foxglove.SceneUpdate: entities added or replaced (triangles and lines), and deletions. */
  applySceneUpdate(message) {
    for (const deletion of message.deletions || []) this.removeEntity(deletion.id);
    for (const entity of message.entities || []) {
      this.removeEntity(entity.id);
      const group = new THREE.Group();
      group.name = entity.id;
      for (const list of entity.triangles || []) {
        const positions = new Float32Array(list.points.length * 3);
        list.points.forEach((p, i) => positions.set([p.x || 0, p.y || 0, p.z || 0], 3 * i));
        const geometry = new THREE.BufferGeometry();
        geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
        if (list.indices && list.indices.length) geometry.setIndex(list.indices);
        geometry.computeVertexNormals();
        const c = list.color || {};
        // A colour per vertex (the printed mesh by its deviation) replaces the list's one colour.
        const perVertex = list.colors && list.colors.length === list.points.length;
        if (perVertex) {
          // Sent as sRGB (as `color` is read); three.js keeps vertex colours linear.
          const colors = new Float32Array(list.colors.length * 3), linear = new THREE.Color();
          list.colors.forEach((color, i) => {
            linear.setRGB(color.r ?? 0, color.g ?? 0, color.b ?? 0, THREE.SRGBColorSpace);
            colors.set([linear.r, linear.g, linear.b], 3 * i);
          });
          geometry.setAttribute("color", new THREE.BufferAttribute(colors, 3));
        }
        group.add(new THREE.Mesh(geometry, new THREE.MeshStandardMaterial({
          color: perVertex ? new THREE.Color(1, 1, 1) : new THREE.Color(c.r ?? 0.6, c.g ?? 0.6, c.b ?? 0.6),
          vertexColors: perVertex, flatShading: true, roughness: 0.8, side: THREE.DoubleSide })));
      }
      for (const line of entity.lines || []) {
        const points = line.points.map((p) => new THREE.Vector3(p.x || 0, p.y || 0, p.z || 0));
        const c = line.color || {};
        group.add(new THREE.Line(new THREE.BufferGeometry().setFromPoints(points),
          new THREE.LineBasicMaterial({ color: new THREE.Color(c.r ?? 0.6, c.g ?? 0.6, c.b ?? 0.6) })));
      }
      this.entities.set(entity.id, group);
      this.updateMeshVisibility();
      this.frame(entity.frame_id || "world").add(group);
    }
  }

  removeEntity(id) {
    const old = this.entities.get(id);
    if (!old) return;
    old.parent?.remove(old);
    old.traverse((object) => {
      object.geometry?.dispose();
      object.material?.dispose();
    });
    this.entities.delete(id);
  }

  setMeshVisible(visible) {
    this.showMesh = visible;
    this.updateMeshVisibility();
  }

  /** The printed mesh in its material's colour, or coloured by its distance to the design. */
  setDeviationVisible(visible) {
    this.showDeviation = visible;
    this.updateMeshVisibility();
  }

  updateMeshVisibility() {
    const plain = this.entities.get("printed_material"), coloured = this.entities.get("printed_deviation");
    if (plain) plain.visible = this.showMesh && !(this.showDeviation && coloured);
    if (coloured) coloured.visible = this.showMesh && this.showDeviation;
  }

  /** The particles at `positions` (x y z per particle), coloured by `values` between low and high
   * (or as categories), drawn as spheres of `radius` (m). */
  setParticles(positions, values, radius, low, high, categories) {
    if (!this.particles) {
      const material = new THREE.ShaderMaterial({
        vertexShader: PARTICLE_VERTEX, fragmentShader: PARTICLE_FRAGMENT,
        uniforms: {
          radius: { value: radius }, pixelScale: { value: 1 }, low: { value: 0 }, high: { value: 1 }, categories: { value: false },
          ramp: { value: RAMP.map((c) => new THREE.Vector3(...c)) }, palette: { value: CATEGORIES.map((c) => new THREE.Vector3(...c)) } },
      });
      this.particles = new THREE.Points(new THREE.BufferGeometry(), material);
      this.particles.frustumCulled = false;
      this.scene.add(this.particles);
    }
    const geometry = this.particles.geometry;
    geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute("value", new THREE.BufferAttribute(values, 1));
    geometry.setDrawRange(0, values.length);
    const uniforms = this.particles.material.uniforms;
    uniforms.radius.value = radius;
    uniforms.low.value = low;
    uniforms.high.value = high;
    uniforms.categories.value = categories;
  }

  /** The middle of an entity's box in the world now (null if there is no such entity). */
  entityCenter(id) {
    const group = this.entities.get(id);
    if (!group) return null;
    group.updateWorldMatrix(true, true);
    return new THREE.Box3().setFromObject(group).getCenter(new THREE.Vector3());
  }

  /** Where a frame's origin is in the world now (null if unknown). */
  framePosition(id) {
    const object = this.frames.get(id);
    if (!object) return null;
    object.updateWorldMatrix(true, false);
    return new THREE.Vector3().setFromMatrixPosition(object.matrixWorld);
  }

  render(follow) {
    const canvas = this.renderer.domElement;
    const width = canvas.clientWidth, height = canvas.clientHeight;
    if (canvas.width !== width || canvas.height !== height) {
      this.renderer.setSize(width, height, false);
      this.camera.aspect = width / Math.max(height, 1);
      this.camera.updateProjectionMatrix();
    }
    if (follow) {
      const nozzle = [...this.frames.keys()].find((id) => id.startsWith("nozzle/"));
      const at = nozzle && this.framePosition(nozzle);
      if (at) {
        this.camera.position.add(at.clone().sub(this.controls.target));
        this.controls.target.copy(at);
      }
    }
    this.controls.update();
    if (this.particles)
      this.particles.material.uniforms.pixelScale.value = height / (2 * Math.tan((this.camera.fov * Math.PI) / 360));
    this.renderer.render(this.scene, this.camera);
  }
}
