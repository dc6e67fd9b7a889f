"""Planning: the three methods (search + CITO), the keyframes formulation and the physics check of a plan."""
