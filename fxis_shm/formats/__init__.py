"""Files and messages other tools read: rosbag2/MCAP bags, ROS 2 message types, a tuple as PNG
files and the synthetic camera's pixel stamp. May import wire and core."""
