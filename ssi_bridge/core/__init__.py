"""The per-joint core of the driver: ROS-free rules of one joint (scale, velocity, frame
checks, health, the REG_PARA1 gate), unit-tested without ROS; ``ros/`` publishes them."""
