// Entry for the fourd viewer's bundled three.js: the core plus the two addons the page uses,
// exposed as one global `THREE` (classic script, so the page works from file:// too).
export * from 'three';
export { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
