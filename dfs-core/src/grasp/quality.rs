//! Grasp quality as GraspIt! defines it: Ferrari-Canny ε with linearised friction cones and the
//! volume of the grasp wrench space.
