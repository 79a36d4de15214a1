"""OpenCV reference for tests/data/opencv-left (run with opencv-python-headless 5.0, numpy).

Writes opencv_corners.csv (findChessboardCorners + cornerSubPix 11x11, as OpenCV's
calibration sample) and prints calibrateCameraExtended's result: free aspect fx 536.074,
fy 536.017, cx 342.370, cy 235.538, RMS 0.4088. Then recalibrates without the 19 corners
where OpenCV's cornerSubPix window (fixed 11 px half-width) reaches past the board edge or
the next corner and drifts (they differ by 0.13-6.2 px from tangent's corners, which agree
with OpenCV's to ~0.001 px everywhere else): fx 533.448, fy 533.579, cx 342.233,
cy 233.903, RMS 0.189.
"""
import cv2, numpy as np, glob, sys, os
here = os.path.dirname(os.path.abspath(__file__))
files = sorted(glob.glob(os.path.join(here, '*.jpg')))
obj = np.zeros((54,3), np.float32); obj[:,:2] = np.mgrid[0:9,0:6].T.reshape(-1,2)*0.025
ops, ips, names = [], [], []
out = open(os.path.join(here, 'opencv_corners.csv'), 'w'); out.write('file,i,j,u_px,v_px\n')
for f in files:
    g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
    ok, c = cv2.findChessboardCorners(g, (9,6), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK)
    if not ok: print('fail', f); continue
    c = cv2.cornerSubPix(g, c, (11,11), (-1,-1), (cv2.TERM_CRITERIA_EPS+cv2.TERM_CRITERIA_COUNT, 30, 0.0001))
    ops.append(obj); ips.append(c); names.append(f)
    for k,p in enumerate(c.reshape(-1,2)):
        out.write('%s,%d,%d,%.6f,%.6f\n' % (f.split('/')[-1], k%9, k//9, p[0], p[1]))
out.close()
rms, K, d, rv, tv, sdi, sde, pve = cv2.calibrateCameraExtended(ops, ips, (640,480), None, None)
print('free aspect rms', rms); print(K); print(d.ravel()); print('std', sdi.ravel()[:9]); print('per view', pve.ravel())
rms2, K2, d2, *_ = cv2.calibrateCamera(ops, ips, (640,480), None, None, flags=cv2.CALIB_FIX_ASPECT_RATIO)
print('fixed aspect rms', rms2); print(K2); print(d2.ravel())

DRIFTED = [('left02.jpg', 0, 0), ('left02.jpg', 0, 1), ('left02.jpg', 1, 1), ('left02.jpg', 0, 2), ('left02.jpg', 1, 2), ('left02.jpg', 0, 3), ('left02.jpg', 0, 4), ('left02.jpg', 0, 5), ('left07.jpg', 0, 4), ('left07.jpg', 6, 4), ('left07.jpg', 8, 4), ('left09.jpg', 8, 5), ('left12.jpg', 7, 5), ('left13.jpg', 8, 0), ('left13.jpg', 8, 1), ('left13.jpg', 8, 2), ('left13.jpg', 8, 3), ('left13.jpg', 8, 4), ('left13.jpg', 8, 5)]
ops2, ips2 = [], []
for f, o, p in zip(names, ops, ips):
    base = os.path.basename(f)
    keep = [k for k in range(54) if (base, k % 9, k // 9) not in DRIFTED]
    ops2.append(o[keep]); ips2.append(p[keep])
rms3, K3, d3, *_ = cv2.calibrateCamera(ops2, ips2, (640,480), None, None)
print('agreed corners rms', rms3); print(K3); print(d3.ravel())
