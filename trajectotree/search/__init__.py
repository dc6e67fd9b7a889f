"""The contact-sequence search (paper Sec. III-A, Algorithm 1): grasps, reachability, stances, the tree."""
