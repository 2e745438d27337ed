"""hcloth_ros: real-time hierarchical mass-spring cloth for ROS 2."""
