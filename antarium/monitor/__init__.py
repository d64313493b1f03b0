"""The browser monitor (`antarium monitor`): a web page of what the dome shows, the path and the loop's health.

It runs in its own process, subscribes to the rig's bus streams (pose, stats, status, events and the decimated
LED stream of `antarium.monitor.led_stream`) and serves one page over HTTP and a websocket (aiohttp).
"""
