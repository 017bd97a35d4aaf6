"""The model editor (`mexone edit`): build a robot from CAD parts in the browser, as Gazebo 7's
Model Editor did for the seed (its chapter 3.2), and save it as URDF, SDF, controllers and a ROS
package. The core (session.py and what it uses) has no GUI; app.py is the page."""
