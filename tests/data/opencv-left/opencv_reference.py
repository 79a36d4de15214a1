import cv2, numpy as np, glob, sys
files = sorted(glob.glob('/work/main/tests/data/opencv-left/*.jpg'))
obj = np.zeros((54,3), np.float32); obj[:,:2] = np.mgrid[0:9,0:6].T.reshape(-1,2)*0.025
ops, ips, names = [], [], []
out = open('/tmp/cvwork/corners.csv','w'); out.write('file,i,j,u_px,v_px\n')
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
