"""Realistic priors: global (K-means palette), local (5x5 variations), human (FaceNet); face-region classifier h."""
