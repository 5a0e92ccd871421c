"""kitti"""
