"""The trackball: ball kinematics, the USB device driver (pyusb), calibration and FicTrac input."""
