"""ROS-free helpers of the tests and benchmarks (never imported by the driver): ``truth``, the
truth oracle of the simulated station."""
