"""Recording: ``fxis record`` into rosbag2/MCAP bags, through the client API, and what a
recording takes next from the rings. May import service and below; not viewers."""
