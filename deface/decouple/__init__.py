"""Light decoupling: the light-mask field f, the face-region field g, ACE, and image composition."""
