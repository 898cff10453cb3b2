"""Outputs: UV textures, OBJ/MTL, params.json/npz, renders and masks."""
