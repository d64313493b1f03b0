"""The limits of a trial log's file name, `<rig>_<UTC yyyymmdd-hhmmss>_<trial>[-<k>].h5`
(`antarium.trial_log.log_path`), shared with the rig config's check of the rig name (which must not import the
trial log)."""

#: the longest file name the file systems a log goes to take (bytes; NAME_MAX of Linux, macOS and Windows' NTFS)
NAME_MAX_BYTES = 255
#: a trial name is cut to this many characters in the file name (`log_path`)
TRIAL_NAME_MAX = 64
#: the longest rig name whose log file names fit NAME_MAX_BYTES: `<rig>_<yyyymmdd-hhmmss>_<trial>-<k>.h5` with
#: the trial name at its longest and a suffix `-<k>` of up to 4 digits (`log_path`)
RIG_NAME_MAX_BYTES = NAME_MAX_BYTES - len("_yyyymmdd-hhmmss_") - TRIAL_NAME_MAX - len("-9999.h5")
