// calib: camera calibration for the rig (contract; issue 10 builds it).
//
// Intrinsics per camera from ChArUco boards or chessboards (OpenCV aruco/calib3d), the
// turntable axis, and each camera's pose `cam_from_table`, refined jointly with a robust loss;
// the versioned RigCalibration JSON file that studio turns into Views (pose of a photo at
// table angle theta follows from theta alone). calib never includes recon or texture.
#pragma once
