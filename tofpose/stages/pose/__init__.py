"""§5: the weighted SVD pose (Eqs. 40-50), the line-of-sight refinement and the pose's
covariance and checks."""
