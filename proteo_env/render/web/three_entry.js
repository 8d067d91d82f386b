// The parts of three.js the episode viewer uses, bundled into three.bundle.js (see README.md here).
export {
  AmbientLight, BufferAttribute, BufferGeometry, Color, ColorManagement, DirectionalLight,
  DynamicDrawUsage, Float32BufferAttribute, InstancedMesh, LineBasicMaterial,
  LineSegments, LinearSRGBColorSpace, Mesh, MeshBasicMaterial, MeshLambertMaterial, Plane, PlaneGeometry,
  PerspectiveCamera, Raycaster, Scene, Vector2, Vector3, WebGLRenderer,
} from 'three';
export { OrbitControls } from 'three/addons/controls/OrbitControls.js';
