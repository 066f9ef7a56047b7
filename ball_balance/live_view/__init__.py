"""The live view in the browser (docs/live_view.md): what the page shows and what it may ask,
without ROS. `model` keeps the scene and states the page shows, `commands` checks what the page
asks for, `server` serves the page and its WebSocket (aiohttp, on a thread of its own), `frames`
JPEG-encodes camera frames off the ROS executor's thread. The node
(ball_balance/nodes/live_view_node.py) connects them to the graph."""
