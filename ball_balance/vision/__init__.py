"""Ball tracking from camera frames (no ROS): plate homography from ArUco markers, HSV ball
segmentation, Kalman filter; `tracker.BallTracker` runs the whole pipeline per frame."""
