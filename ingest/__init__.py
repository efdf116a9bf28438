"""Import recorded robot data into a PBD-AG service: frame sources (a 7-Scenes/TUM-like folder, a
ROS 2 bag), detector plugins that turn a frame into masks, and the batches sent to the API.

Layout: `frames` (what a source yields), `transforms` (tf chains, time sync), `folder` and
`rosbag` (the sources), `detectors` (the plugin interface and the shipped plugins), `wire` (frames
and detections as the wire's batch request), `sink` (the one module that talks HTTP), `pipeline`
(read, detect, batch, send), `cli` (`pbdag ingest folder|rosbag`).
"""
