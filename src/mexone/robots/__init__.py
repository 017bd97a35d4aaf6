"""The built-in robots (Mex-One and the example robots), each a package of its URDF, meshes and
controller YAML."""
