"""Navigation: where the robot is and how it gets where it goes.

Occupancy maps in the ROS ``map_server`` format, building them from laser scans (scan matching on
top of odometry), Monte Carlo localization against a map, and path planning on the inflated map.
Pure computation on numpy arrays (compiled with numba where it matters): it imports
``twin.core`` and nothing else of the project, no device library, no MuJoCo, so the same code
runs in the twin and on the robot.
"""
