"""The scenes that ship with remoteenv; each folder is one env package.

Importing a scene package registers its Gymnasium id (agent side only: the
scene script itself runs in the sim process).
"""
