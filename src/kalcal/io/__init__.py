"""Input and output: log readers (CSV, Parquet, ROS bags, PX4 ULog) with validation, result writers, and an output folder written as one set."""
