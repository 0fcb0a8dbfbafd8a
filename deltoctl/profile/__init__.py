"""Device profiles: the model, its YAML and URDF/xacro loaders, and the exporter."""
