//! The ROS messages a Soft Bubble recording carries, decoded from (and, for tests and demo recordings, encoded to)
//! their wire formats: ROS 2's CDR (XCDR1, either byte order, fields aligned to their size from the end of the
//! 4-byte encapsulation header) and ROS 1's serialisation (packed little-endian, a `seq` field in the header).
//!
//! Messages: `sensor_msgs/Image` (depth in `16UC1`/`mono16` millimetres or `32FC1` metres), `sensor_msgs/PointCloud2`
//! (float x, y, z fields in the camera's optical frame), `geometry_msgs/PoseStamped` and `geometry_msgs/Pose2D`
//! (the object's SE(2) pose). Every length is checked against the buffer before anything is allocated.

/// How a channel's messages are serialised (MCAP's `message_encoding`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 2: CDR with an encapsulation header.
    Cdr,
    /// ROS 1: packed little-endian.
    Ros1,
}

impl Encoding {
    /// From an MCAP channel's `message_encoding` (`cdr`, `ros1`).
    pub fn from_mcap(name: &str) -> Option<Self> {
        match name {
            "cdr" => Some(Encoding::Cdr),
            "ros1" => Some(Encoding::Ros1),
            _ => None,
        }
    }
}

/// A `sensor_msgs/Image`, header stamp in nanoseconds.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageMsg {
    pub stamp_ns: u64,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: bool,
    pub step: u32,
    pub data: Vec<u8>,
}

/// A field of a `sensor_msgs/PointCloud2`.
#[derive(Clone, Debug, PartialEq)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    /// 1 int8, 2 uint8, 3 int16, 4 uint16, 5 int32, 6 uint32, 7 float32, 8 float64.
    pub datatype: u8,
    pub count: u32,
}

/// A `sensor_msgs/PointCloud2`.
#[derive(Clone, Debug, PartialEq)]
pub struct PointCloudMsg {
    pub stamp_ns: u64,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Vec<u8>,
}

/// An SE(2) pose read from `geometry_msgs/PoseStamped` (x, y and the yaw of its quaternion) or `Pose2D`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose2dMsg {
    /// Header stamp, nanoseconds (`None` for `Pose2D`, which has no header: the MCAP log time is used).
    pub stamp_ns: Option<u64>,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

/// Field-by-field reader over one message.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    /// Alignment origin (CDR: after the encapsulation header); `None` = packed (ROS 1).
    align_base: Option<usize>,
    little: bool,
    ros1: bool,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8], encoding: Encoding) -> Result<Self, String> {
        match encoding {
            Encoding::Ros1 => Ok(Self {
                buf,
                pos: 0,
                align_base: None,
                little: true,
                ros1: true,
            }),
            Encoding::Cdr => {
                let head = buf
                    .get(..4)
                    .ok_or("shorter than the 4-byte CDR encapsulation header")?;
                let little = match (head[0], head[1]) {
                    (0, 0) => false,
                    (0, 1) => true,
                    (a, b) => {
                        return Err(format!(
                            "CDR encapsulation {a:#04x}{b:02x} is not plain CDR (0x0000 big-endian, 0x0001 little-endian)"
                        ))
                    }
                };
                Ok(Self {
                    buf,
                    pos: 4,
                    align_base: Some(4),
                    little,
                    ros1: false,
                })
            }
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if let Some(base) = self.align_base {
            let a = n.min(8);
            if a > 1 {
                let off = (self.pos - base) % a;
                if off != 0 {
                    self.pos += a - off;
                }
            }
        }
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        let end = end.ok_or_else(|| {
            format!(
                "message ends inside {what} (needs {n} bytes at offset {}, has {})",
                self.pos,
                self.buf.len()
            )
        })?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn u8(&mut self, what: &str) -> Result<u8, String> {
        Ok(self.take(1, what)?[0])
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        let b: [u8; 4] = self
            .take(4, what)?
            .try_into()
            .map_err(|_| what.to_string())?;
        Ok(if self.little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    fn f64(&mut self, what: &str) -> Result<f64, String> {
        let b: [u8; 8] = self
            .take(8, what)?
            .try_into()
            .map_err(|_| what.to_string())?;
        Ok(if self.little {
            f64::from_le_bytes(b)
        } else {
            f64::from_be_bytes(b)
        })
    }

    /// A byte sequence (u32 count + bytes), checked against the remaining buffer before copying.
    fn bytes(&mut self, what: &str) -> Result<Vec<u8>, String> {
        let n = self.u32(what)? as usize;
        Ok(self.take_unaligned(n, what)?.to_vec())
    }

    fn take_unaligned(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let base = self.align_base.take();
        let r = self.take(n, what);
        self.align_base = base;
        r
    }

    fn string(&mut self, what: &str) -> Result<String, String> {
        let n = self.u32(what)? as usize;
        let raw = self.take_unaligned(n, what)?;
        // CDR strings count their terminating NUL; ROS 1 strings have none.
        let raw = if self.ros1 {
            raw
        } else {
            raw.strip_suffix(&[0]).unwrap_or(raw)
        };
        String::from_utf8(raw.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }

    /// `std_msgs/Header` (ROS 1: seq, stamp, frame_id; ROS 2: stamp, frame_id); the stamp in nanoseconds.
    fn header(&mut self) -> Result<u64, String> {
        if self.ros1 {
            self.u32("header.seq")?;
        }
        let sec = self.u32("header.stamp.sec")?;
        let nsec = self.u32("header.stamp.nanosec")?;
        self.string("header.frame_id")?;
        // ROS 2's sec is an int32: negative stamps (before 1970) clamp to 0.
        let sec = if self.ros1 {
            sec as u64
        } else {
            (sec as i32).max(0) as u64
        };
        Ok(sec * 1_000_000_000 + nsec as u64)
    }
}

/// Decode a `sensor_msgs/Image`.
pub fn decode_image(
    buf: &[u8],
    encoding: Encoding,
) -> Result<ImageMsg, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("sensor_msgs/Image", || {
        let mut r = Reader::new(buf, encoding)?;
        let stamp_ns = r.header()?;
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        let enc = r.string("encoding")?;
        let is_bigendian = r.u8("is_bigendian")? != 0;
        let step = r.u32("step")?;
        let data = r.bytes("data")?;
        Ok(ImageMsg {
            stamp_ns,
            height,
            width,
            encoding: enc,
            is_bigendian,
            step,
            data,
        })
    })
}

/// Decode a `sensor_msgs/PointCloud2`.
pub fn decode_point_cloud(
    buf: &[u8],
    encoding: Encoding,
) -> Result<PointCloudMsg, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("sensor_msgs/PointCloud2", || {
        let mut r = Reader::new(buf, encoding)?;
        let stamp_ns = r.header()?;
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        let n = r.u32("fields")? as usize;
        // A field takes at least 13 bytes: refuse counts the buffer cannot hold before allocating.
        if n > buf.len() / 13 + 1 {
            return Err(format!("claims {n} point fields in {} bytes", buf.len()));
        }
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            fields.push(PointField {
                name: r.string("field name")?,
                offset: r.u32("field offset")?,
                datatype: r.u8("field datatype")?,
                count: r.u32("field count")?,
            });
        }
        let is_bigendian = r.u8("is_bigendian")? != 0;
        let point_step = r.u32("point_step")?;
        let row_step = r.u32("row_step")?;
        let data = r.bytes("data")?;
        Ok(PointCloudMsg {
            stamp_ns,
            height,
            width,
            fields,
            is_bigendian,
            point_step,
            row_step,
            data,
        })
    })
}

/// Decode a `geometry_msgs/PoseStamped` into its SE(2) part (x, y and the yaw about z of its orientation).
pub fn decode_pose_stamped(
    buf: &[u8],
    encoding: Encoding,
) -> Result<Pose2dMsg, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("geometry_msgs/PoseStamped", || {
        let mut r = Reader::new(buf, encoding)?;
        let stamp_ns = r.header()?;
        let x = r.f64("position.x")?;
        let y = r.f64("position.y")?;
        r.f64("position.z")?;
        let (qx, qy, qz, qw) = (
            r.f64("orientation.x")?,
            r.f64("orientation.y")?,
            r.f64("orientation.z")?,
            r.f64("orientation.w")?,
        );
        // A zero or far-from-unit quaternion is no rotation (an uninitialised message); its "yaw" would be arbitrary.
        let norm = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        if !(0.9..=1.1).contains(&norm) {
            return Err(format!(
                "orientation ({qx}, {qy}, {qz}, {qw}) is not a unit quaternion (norm {norm:.3})"
            ));
        }
        // Normalised only when it is not unit already (a division by 1 ± ulp would move an exact yaw by an ulp).
        let (qx, qy, qz, qw) = if (norm - 1.0).abs() > 1e-9 {
            (qx / norm, qy / norm, qz / norm, qw / norm)
        } else {
            (qx, qy, qz, qw)
        };
        let theta = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
        finite_pose(Pose2dMsg {
            stamp_ns: Some(stamp_ns),
            x,
            y,
            theta,
        })
    })
}

/// Decode a `geometry_msgs/Pose2D`.
pub fn decode_pose2d(
    buf: &[u8],
    encoding: Encoding,
) -> Result<Pose2dMsg, crate::error::InvalidInput> {
    crate::error::InvalidInput::wrap("geometry_msgs/Pose2D", || {
        let mut r = Reader::new(buf, encoding)?;
        finite_pose(Pose2dMsg {
            stamp_ns: None,
            x: r.f64("x")?,
            y: r.f64("y")?,
            theta: r.f64("theta")?,
        })
    })
}

fn finite_pose(p: Pose2dMsg) -> Result<Pose2dMsg, String> {
    if p.x.is_finite() && p.y.is_finite() && p.theta.is_finite() {
        Ok(p)
    } else {
        Err(format!(
            "pose ({}, {}, {}) is not finite",
            p.x, p.y, p.theta
        ))
    }
}

/// Little-endian CDR writer (ROS 2), for demo and test recordings.
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    pub fn new() -> Self {
        Self {
            buf: vec![0, 1, 0, 0],
        }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }

    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }

    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32);
        self.buf.extend_from_slice(b);
        self
    }

    pub fn header(&mut self, stamp_ns: u64, frame_id: &str) -> &mut Self {
        self.u32((stamp_ns / 1_000_000_000) as u32)
            .u32((stamp_ns % 1_000_000_000) as u32)
            .string(frame_id)
    }

    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// Encode a `sensor_msgs/Image` as ROS 2 CDR.
pub fn encode_image(m: &ImageMsg, frame_id: &str) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.header(m.stamp_ns, frame_id)
        .u32(m.height)
        .u32(m.width)
        .string(&m.encoding)
        .u8(m.is_bigendian as u8)
        .u32(m.step)
        .bytes(&m.data);
    w.finish()
}

/// Encode a `sensor_msgs/PointCloud2` as ROS 2 CDR.
pub fn encode_point_cloud(m: &PointCloudMsg, frame_id: &str) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.header(m.stamp_ns, frame_id)
        .u32(m.height)
        .u32(m.width)
        .u32(m.fields.len() as u32);
    for f in &m.fields {
        w.string(&f.name).u32(f.offset).u8(f.datatype).u32(f.count);
    }
    w.u8(m.is_bigendian as u8)
        .u32(m.point_step)
        .u32(m.row_step)
        .bytes(&m.data)
        .u8(1);
    w.finish()
}

/// Encode a `geometry_msgs/PoseStamped` (z = 0, rotation about z by `theta`) as ROS 2 CDR.
pub fn encode_pose_stamped(stamp_ns: u64, x: f64, y: f64, theta: f64, frame_id: &str) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.header(stamp_ns, frame_id);
    planar_pose(&mut w, x, y, theta);
    w.finish()
}

/// A `geometry_msgs/Pose` in the table plane: position (x, y, 0), rotation about z by `theta`.
fn planar_pose(w: &mut CdrWriter, x: f64, y: f64, theta: f64) {
    w.f64(x)
        .f64(y)
        .f64(0.0)
        .f64(0.0)
        .f64(0.0)
        .f64((theta / 2.0).sin())
        .f64((theta / 2.0).cos());
}

/// Encode a `geometry_msgs/PoseWithCovarianceStamped` (z = 0, rotation about z by `theta`; `covariance` row-major
/// over x, y, z and the rotations about x, y, z) as ROS 2 CDR.
pub fn encode_pose_with_covariance_stamped(
    stamp_ns: u64,
    frame_id: &str,
    [x, y, theta]: [f64; 3],
    covariance: &[f64; 36],
) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.header(stamp_ns, frame_id);
    planar_pose(&mut w, x, y, theta);
    for &c in covariance {
        w.f64(c);
    }
    w.finish()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn image_round_trips_through_cdr_with_alignment_padding() {
        let m = ImageMsg {
            stamp_ns: 1_700_000_000_123_456_789,
            height: 2,
            width: 3,
            encoding: "16UC1".into(),
            is_bigendian: false,
            step: 6,
            data: (0..12).collect(),
        };
        // "bubble" (7 bytes with NUL) after the 8-byte stamp leaves the next u32 unaligned: padding is exercised.
        let bytes = encode_image(&m, "bubble");
        assert_eq!(decode_image(&bytes, Encoding::Cdr).unwrap(), m);
        // Every truncation is an error, never a panic.
        for n in 0..bytes.len() {
            assert!(decode_image(&bytes[..n], Encoding::Cdr).is_err(), "{n}");
        }
    }

    #[test]
    fn pose_with_covariance_starts_as_a_pose_stamped_and_ends_with_its_covariance() {
        // Invariant: PoseWithCovarianceStamped is PoseStamped's fields followed by 36 float64 (already 8-aligned), so
        // the PoseStamped decoder reads its pose and the last 288 bytes are the covariance.
        let cov: [f64; 36] = std::array::from_fn(|i| i as f64 * 0.5);
        let bytes =
            encode_pose_with_covariance_stamped(3_000_000_007, "bubble", [0.01, -0.02, 0.7], &cov);
        let pose = decode_pose_stamped(&bytes, Encoding::Cdr).unwrap();
        assert!((pose.x - 0.01).abs() < 1e-12 && (pose.y + 0.02).abs() < 1e-12);
        assert!((pose.theta - 0.7).abs() < 1e-12);
        let tail = &bytes[bytes.len() - 288..];
        for (i, c) in tail.chunks(8).enumerate() {
            assert_eq!(f64::from_le_bytes(c.try_into().unwrap()), cov[i]);
        }
        assert_eq!(
            bytes.len() - 288,
            encode_pose_stamped(3_000_000_007, 0.01, -0.02, 0.7, "bubble").len()
        );
    }

    #[test]
    fn hand_assembled_cdr_image_decodes() {
        // Independent truth: bytes laid out by hand following the CDR rules (not by CdrWriter).
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(5u32.to_le_bytes()); // sec
        b.extend(7u32.to_le_bytes()); // nanosec
        b.extend(2u32.to_le_bytes()); // frame_id length incl. NUL
        b.extend(b"c\0");
        b.extend([0, 0]); // pad to 4
        b.extend(1u32.to_le_bytes()); // height
        b.extend(1u32.to_le_bytes()); // width
        b.extend(6u32.to_le_bytes());
        b.extend(b"32FC1\0");
        b.push(0); // is_bigendian
        b.push(0); // pad: offset 31 -> 32 (data offset 28 from the header)
        b.extend(4u32.to_le_bytes()); // step
        b.extend(4u32.to_le_bytes()); // data length
        b.extend(0.25f32.to_le_bytes());
        let m = decode_image(&b, Encoding::Cdr).unwrap();
        assert_eq!(m.stamp_ns, 5_000_000_007);
        assert_eq!((m.width, m.height, m.step), (1, 1, 4));
        assert_eq!(m.encoding, "32FC1");
        assert_eq!(m.data, 0.25f32.to_le_bytes());
    }

    #[test]
    fn ros1_image_decodes() {
        let mut b = Vec::new();
        b.extend(9u32.to_le_bytes()); // seq
        b.extend(1u32.to_le_bytes());
        b.extend(2u32.to_le_bytes());
        b.extend(3u32.to_le_bytes());
        b.extend(b"cam"); // no NUL, no padding
        b.extend(1u32.to_le_bytes());
        b.extend(2u32.to_le_bytes());
        b.extend(6u32.to_le_bytes());
        b.extend(b"mono16");
        b.push(1);
        b.extend(4u32.to_le_bytes());
        b.extend(4u32.to_le_bytes());
        b.extend([1, 2, 3, 4]);
        let m = decode_image(&b, Encoding::Ros1).unwrap();
        assert_eq!(m.stamp_ns, 1_000_000_002);
        assert_eq!((m.width, m.height), (2, 1));
        assert!(m.is_bigendian);
        assert_eq!(m.data, vec![1, 2, 3, 4]);
    }

    #[test]
    fn pose_stamped_yaw_and_point_cloud_round_trip() {
        let b = encode_pose_stamped(42, 0.01, -0.02, 2.5, "world");
        let p = decode_pose_stamped(&b, Encoding::Cdr).unwrap();
        assert_eq!(p.stamp_ns, Some(42));
        assert!((p.x - 0.01).abs() < 1e-15 && (p.y + 0.02).abs() < 1e-15);
        assert!((p.theta - 2.5).abs() < 1e-12, "{}", p.theta);
        // The orientation is the message's last four doubles: a zero quaternion is refused, not read as a yaw of 0.
        let mut zero = b.clone();
        let n = zero.len();
        zero[n - 32..].fill(0);
        let e = decode_pose_stamped(&zero, Encoding::Cdr).unwrap_err();
        assert!(e.message.contains("not a unit quaternion"), "{e}");
        let pc = PointCloudMsg {
            stamp_ns: 3,
            height: 1,
            width: 1,
            fields: vec![PointField {
                name: "x".into(),
                offset: 0,
                datatype: 7,
                count: 1,
            }],
            is_bigendian: false,
            point_step: 4,
            row_step: 4,
            data: vec![0, 0, 128, 63],
        };
        let bytes = encode_point_cloud(&pc, "cam");
        assert_eq!(decode_point_cloud(&bytes, Encoding::Cdr).unwrap(), pc);
    }

    #[test]
    fn absurd_lengths_are_refused_before_allocating() {
        let mut w = CdrWriter::new();
        w.header(0, "").u32(1).u32(1).u32(u32::MAX); // claims 4 G point fields
        assert!(decode_point_cloud(&w.finish(), Encoding::Cdr).is_err());
        let mut w = CdrWriter::new();
        w.header(0, "")
            .u32(1)
            .u32(1)
            .string("16UC1")
            .u8(0)
            .u32(2)
            .u32(u32::MAX);
        assert!(decode_image(&w.finish(), Encoding::Cdr).is_err());
    }
}
